"""Figures, tables and output folders."""
