"""Find a script that starts worker processes outside ``if __name__ == "__main__":``.

Worker processes started with ``forkserver`` or ``spawn`` import the user's
``__main__`` script again before they compute anything.  If the script's top
level starts workers itself (``monte_carlo(..., backend=2)`` not under the
guard), every worker fails while starting and the pool breaks.  Python's own
message is printed by each worker; the parent process only sees a broken
pool.  :func:`unguarded_main_call` lets the parent name the script and the line.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

__all__ = ["guarded_lines", "unguarded_main_call"]


def _is_main_test(test: ast.expr) -> bool:
    """Whether ``test`` is ``__name__ == "__main__"`` (either way round)."""
    if not (isinstance(test, ast.Compare) and len(test.ops) == 1 and isinstance(test.ops[0], ast.Eq)):
        return False
    sides = (test.left, test.comparators[0])
    has_name = any(isinstance(s, ast.Name) and s.id == "__name__" for s in sides)
    has_main = any(isinstance(s, ast.Constant) and s.value == "__main__" for s in sides)
    return has_name and has_main


def guarded_lines(source: str) -> list[range]:
    """The line ranges of ``source`` under a top-level ``if __name__ == "__main__":``.

    Parameters
    ----------
    source
        The text of a Python module.

    Returns
    -------
    list of range
        1-based line numbers, one range per guard (its body and any ``else``).
    """
    tree = ast.parse(source)
    return [
        range(node.lineno, (node.end_lineno or node.lineno) + 1)
        for node in tree.body
        if isinstance(node, ast.If) and _is_main_test(node.test)
    ]


def unguarded_main_call() -> tuple[str, int] | None:
    """The ``__main__`` script and line that led here from its top level, outside the guard.

    Walks the call stack to the frame running the ``__main__`` module's top
    level.  Returns ``(path, line)`` if that line is not under a top-level
    ``if __name__ == "__main__":``, and None if it is, if the call did not come
    from a script's top level (an interactive session, a notebook, a function
    called later), or if the script cannot be read.
    """
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if main is None or not isinstance(path, str):
        return None
    frame = sys._getframe(1)
    while frame is not None and not (frame.f_code.co_name == "<module>" and frame.f_globals is vars(main)):
        frame = frame.f_back
    if frame is None:
        return None
    line = frame.f_lineno
    try:
        guards = guarded_lines(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, SyntaxError, ValueError):
        return None
    if any(line in g for g in guards):
        return None
    return path, line
