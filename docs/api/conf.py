"""Sphinx configuration of pursuit's API reference (``make docs``; built with -W, warnings are errors).

The reference is generated from the numpy-style docstrings by autodoc and napoleon.  The user guide
is the Markdown in docs/ (read on the repository host); this site links to it rather than rebuilding it.
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "src"))  # document these sources, not an installed copy

import pursuit  # noqa: E402

project = "pursuit"
author = "pursuit developers"
copyright = "pursuit developers, BSD-3-Clause"
release = pursuit.__version__
version = ".".join(release.split(".")[:2])

extensions = ["sphinx.ext.autodoc", "sphinx.ext.napoleon", "sphinx.ext.intersphinx"]
exclude_patterns = ["_build"]
nitpicky = False  # types in prose ("array (K, M, n)") are not all resolvable targets

autodoc_default_options = {"members": True, "show-inheritance": True, "member-order": "bysource"}
autodoc_typehints = "description"
autodoc_typehints_format = "short"
autodoc_preserve_defaults = True
autoclass_content = "class"

napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False

intersphinx_mapping = {}  # offline builds: no inventories fetched

html_theme = "alabaster"
html_title = f"pursuit {release} API reference"
html_show_sourcelink = False
