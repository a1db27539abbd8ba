"""The one writer of the generated blocks in README.md and docs/: text between
``<!-- generated:NAME -->`` and ``<!-- /generated:NAME -->`` comes from a results file, written by
a script in experiments/, whose ``--check`` (run by the tests) fails when a block is stale."""

from __future__ import annotations

import argparse
import re
from pathlib import Path
from typing import Callable


def fill_block(text: str, name: str, body: str, *, where: object = "text", required: bool = True) -> str:
    """``text`` with the block ``name`` holding ``body``; a missing block is an error naming
    ``where`` unless not ``required`` (then ``text`` comes back unchanged)."""
    pattern = re.compile(rf"(<!-- generated:{name} -->).*?(<!-- /generated:{name} -->)", re.S)
    if required and not pattern.search(text):
        raise ValueError(f"{where}: no <!-- generated:{name} --> ... <!-- /generated:{name} --> markers")
    return pattern.sub(lambda m: m.group(1) + "\n" + body + "\n" + m.group(2), text)


def update(path: Path, new_text: str, check: bool, how_to_fix: str) -> int:
    """Write ``new_text`` to ``path`` (exit code 0), or with ``check`` only compare: 1 and a
    message saying ``how_to_fix`` if the file differs."""
    if new_text == path.read_text():
        return 0
    if check:
        print(f"{path}: out of date with its results; {how_to_fix}")
        return 1
    path.write_text(new_text)
    return 0



def block_main(script: str, path: Path, name: str, body: Callable[[], str], argv=None) -> int:
    """The command line of ``script`` (its ``__file__``), whose one output is the block ``name``
    of ``path``: rewrite the block and print it, or with ``--check`` only compare (exit 1 if
    stale). ``body`` is computed once."""
    ap = argparse.ArgumentParser(description=f"write the {name} block of {path.name}")
    ap.add_argument("--check", action="store_true", help="exit 1 if that block is stale")
    args = ap.parse_args(argv)
    text = body()
    new = fill_block(path.read_text(), name, text, where=path)
    status = update(path, new, args.check, f"run python experiments/{Path(script).name}")
    if not args.check:
        print(text)
    return status
