"""Where the example model files, data and scripts are, installed or not."""

from __future__ import annotations

from pathlib import Path

__all__ = ["examples_dir"]


def examples_dir() -> Path:
    """The folder of the examples: model files, recorded data and scripts.

    The wheel ships the repository's ``examples/`` as ``pursuit/_examples``;
    an editable install or a source checkout uses ``examples/`` itself.

    Returns
    -------
    pathlib.Path
        The folder; ``examples_dir() / "wsn-range.toml"`` is the WSN model file
        and ``examples_dir() / "data" / "wsn-range.csv"`` its recorded data
        (docs/track.md).

    Raises
    ------
    FileNotFoundError
        If neither copy exists (a broken installation).

    Examples
    --------
    >>> import shutil, pursuit
    >>> shutil.copytree(pursuit.examples_dir(), "pursuit-examples")  # doctest: +SKIP
    """
    packaged = Path(__file__).parent / "_examples"
    if packaged.is_dir():
        return packaged
    source = Path(__file__).resolve().parents[2] / "examples"
    if source.is_dir():
        return source
    raise FileNotFoundError(f"the pursuit examples are missing: neither {packaged} nor {source} exists; reinstall pursuit")
