"""Fixtures for the report tests: a real Chromium, installed from Debian's packages when missing."""

from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from .browser import find_chromium

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"
INSTALL_LOCK = Path("/tmp/pursuit-chromium-install.lock")
PACKAGES = ["chromium", "fonts-dejavu-core"]


def _apt(args: list[str], timeout: int) -> subprocess.CompletedProcess:
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    return subprocess.run(["apt-get", *args], env=env, capture_output=True, text=True, timeout=timeout)


def _install_chromium() -> str:
    """Install Debian's chromium with apt-get; returns '' on success or the reason it failed."""
    if not shutil.which("apt-get"):
        return "apt-get is not available"
    if os.geteuid() != 0:
        return "installing packages needs root"
    try:
        res = _apt(["install", "-y", "--no-install-recommends", *PACKAGES], 900)
        if res.returncode != 0:  # a fresh machine may have no package lists yet
            upd = _apt(["update"], 600)
            if upd.returncode != 0:
                return f"apt-get update failed: {upd.stderr.strip()[-500:]}"
            res = _apt(["install", "-y", "--no-install-recommends", *PACKAGES], 900)
    except subprocess.TimeoutExpired as e:
        return f"apt-get timed out: {e}"
    if res.returncode != 0:
        return f"apt-get install chromium failed: {res.stderr.strip()[-500:]}"
    return ""


@pytest.fixture(scope="session")
def chromium() -> str:
    """Path of a Chromium binary; installs Debian's package when none is found.

    Skips (with the reason) only when installation is impossible here.
    Parallel test workers take a lock so that only one runs apt-get.
    """
    path = find_chromium()
    if path:
        return path
    with INSTALL_LOCK.open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        path = find_chromium()  # another worker may have installed it meanwhile
        if path:
            return path
        reason = _install_chromium()
    path = find_chromium()
    if not path:
        pytest.skip(f"Chromium is not installed and could not be installed: {reason or 'no binary after install'}")
    return path


@pytest.fixture(scope="session")
def artifacts() -> Path:
    """``test-artifacts/`` at the repository root (git-ignored), for screenshots."""
    ARTIFACTS.mkdir(exist_ok=True)
    return ARTIFACTS
