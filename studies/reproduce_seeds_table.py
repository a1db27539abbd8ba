"""docs/reproduce.md's three-seed tables, written from the committed run's own tables.md.

    python studies/reproduce_seeds_table.py           # rewrite the docs block
    python studies/reproduce_seeds_table.py --check   # exit 1 if the docs block is stale

Reads ``results/reproduce_seeds/tables.md`` (written by ``furuta-gym reproduce --seeds …``: each
cell mean ± std over the model seeds, beside the paper's) and ``run.json`` (command, seeds,
machine, date), and puts both tables and their summary into the ``reproduce-seeds`` block.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import block_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RUN = ROOT / "results" / "reproduce_seeds"
DOCS = ROOT / "docs" / "reproduce.md"
NAME = "reproduce-seeds"  # the docs/reproduce.md block this writes


def tables() -> str:
    run = json.loads((RUN / "run.json").read_text())
    text = (RUN / "tables.md").read_text()
    start = text.index("## Table 1")
    # one heading level down: the block sits under a docs section
    body = re.sub(r"^## ", "#### ", text[start:].strip(), flags=re.M)
    command = re.sub(r"--out \S+", "--out <folder>", run["command"])
    machine = run["machine"]
    head = (
        f"`{command}` ({run['date_utc'][:16].replace('T', ' ')} UTC, {machine.get('cpu', 'cpu')}, "
        f"{machine['cpu_count']} cores), model seeds {', '.join(map(str, run['config']['seeds']))} on the data of "
        f"seed {run['config']['data_seed']}; each cell mean ± sample standard deviation over the seeds. Files: "
        "[results/reproduce_seeds/](../results/reproduce_seeds/tables.md)."
    )
    return head + "\n\n" + body


def main(argv=None) -> int:
    return block_main(__file__, DOCS, NAME, tables, argv)


if __name__ == "__main__":
    raise SystemExit(main())
