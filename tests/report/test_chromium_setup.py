"""The browser test's set-up: it installs Chromium, and under CI it fails rather than skips."""

from __future__ import annotations

import subprocess

import pytest

from . import conftest
from .browser import FLAGS


def _no_chromium(monkeypatch, tmp_path, reason: str):
    monkeypatch.setattr(conftest, "find_chromium", lambda: None)
    monkeypatch.setattr(conftest, "_install_chromium", lambda: reason)
    monkeypatch.setattr(conftest, "INSTALL_LOCK", tmp_path / "lock")


def test_missing_chromium_fails_under_ci(monkeypatch, tmp_path):
    _no_chromium(monkeypatch, tmp_path, "no network")
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="no network.*CI is set"):
        conftest.get_chromium()


@pytest.mark.parametrize("value", [None, "", "0", "false"])
def test_missing_chromium_skips_outside_ci(monkeypatch, tmp_path, value):
    _no_chromium(monkeypatch, tmp_path, "no network")
    if value is None:
        monkeypatch.delenv("CI", raising=False)
    else:
        monkeypatch.setenv("CI", value)
    with pytest.raises(pytest.skip.Exception, match="no network"):
        conftest.get_chromium()


def test_not_root_installs_through_sudo_n(monkeypatch):
    calls = []

    def fake_run(cmd, **kw):
        calls.append(cmd)
        return subprocess.CompletedProcess(cmd, 0, "", "")

    monkeypatch.setattr(conftest.os, "geteuid", lambda: 1000)
    monkeypatch.setattr(conftest.shutil, "which", lambda name: f"/usr/bin/{name}")
    monkeypatch.setattr(conftest.subprocess, "run", fake_run)
    assert conftest._install_chromium() == ""
    assert calls and calls[0][:2] == ["sudo", "-n"] and "apt-get" in calls[0]  # never a password prompt
    monkeypatch.setattr(conftest.shutil, "which", lambda name: None if name == "sudo" else f"/usr/bin/{name}")
    assert "sudo is not available" in conftest._install_chromium()


def test_root_installs_without_sudo(monkeypatch):
    calls = []
    monkeypatch.setattr(conftest.os, "geteuid", lambda: 0)
    monkeypatch.setattr(conftest.shutil, "which", lambda name: f"/usr/bin/{name}")
    monkeypatch.setattr(conftest.subprocess, "run", lambda cmd, **kw: calls.append(cmd) or subprocess.CompletedProcess(cmd, 0, "", ""))
    assert conftest._install_chromium() == ""
    assert calls[0][0] == "apt-get"


def test_chromium_flags_suit_containers():
    assert "--disable-dev-shm-usage" in FLAGS and "--headless" in FLAGS
