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


def under_ci() -> bool:
    """True when the environment variable ``CI`` is set (to anything but '', 0, false or no)."""
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def _apt(args: list[str], timeout: int, sudo: bool = False) -> subprocess.CompletedProcess:
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    prefix = ["sudo", "-n", "env", "DEBIAN_FRONTEND=noninteractive"] if sudo else []
    return subprocess.run([*prefix, "apt-get", *args], env=env, capture_output=True, text=True, timeout=timeout)


def _install_chromium() -> str:
    """Install Debian's chromium with apt-get (through ``sudo -n`` when not root); '' on success, else why not."""
    if not shutil.which("apt-get"):
        return "apt-get is not available"
    sudo = os.geteuid() != 0
    if sudo and not shutil.which("sudo"):
        return "installing packages needs root, and sudo is not available"
    try:
        res = _apt(["install", "-y", "--no-install-recommends", *PACKAGES], 900, sudo)
        if res.returncode != 0:  # a fresh machine may have no package lists yet
            upd = _apt(["update"], 600, sudo)
            if upd.returncode != 0:
                return f"{'sudo -n ' if sudo else ''}apt-get update failed: {upd.stderr.strip()[-500:]}"
            res = _apt(["install", "-y", "--no-install-recommends", *PACKAGES], 900, sudo)
    except subprocess.TimeoutExpired as e:
        return f"apt-get timed out: {e}"
    if res.returncode != 0:
        return f"{'sudo -n ' if sudo else ''}apt-get install chromium failed: {res.stderr.strip()[-500:]}"
    return ""


def get_chromium() -> str:
    """Path of a Chromium binary, installing Debian's package when none is found.

    When none can be had, the test fails under CI (``CI`` set: a check that
    silently does not run is no check) and is skipped with the reason
    elsewhere.  Parallel test workers take a lock so that only one runs
    apt-get.
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
        msg = f"Chromium is not installed and could not be installed: {reason or 'no binary after install'}"
        if under_ci():
            pytest.fail(f"{msg} (CI is set, so the browser test must run)", pytrace=False)
        pytest.skip(msg)
    return path


@pytest.fixture(scope="session")
def chromium() -> str:
    """Path of a Chromium binary (see :func:`get_chromium`)."""
    return get_chromium()


@pytest.fixture(scope="session")
def artifacts() -> Path:
    """``test-artifacts/`` at the repository root (git-ignored), for screenshots."""
    ARTIFACTS.mkdir(exist_ok=True)
    return ARTIFACTS
