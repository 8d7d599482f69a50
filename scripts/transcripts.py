"""Refresh the console transcripts of the README and docs/guide/ by running their commands.

A transcript is a ```console block right after a ``<!-- transcript -->`` line. Its ``$ ``
lines are commands; everything else is their output, which this script rewrites with what the
commands print now (stdout and stderr, as a terminal 100 columns wide shows them). Each page
runs in a fresh working directory with its own store (``AOC_STORE=./corpora``), its blocks in
page order, so a later block sees what an earlier one made. Before the first block:

* ``<!-- transcript-file: NAME -->`` just before a fenced block writes that block's text to NAME;
* ``<!-- transcript-setup`` ... ``-->`` runs the shell lines inside (invisible when rendered).

    python scripts/transcripts.py                    # every page with transcripts
    python scripts/transcripts.py docs/guide/ingest.md --check   # exit 1 if a page would change

Commands run with the repository's ``.venv/bin`` first on PATH, one thread each for torch and
BLAS, and a fixed seed wherever the page gives one, so a refresh changes only what the code
changed (and timings).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FENCE = re.compile(r"^```")


def _env(workdir: Path) -> dict:
    env = dict(os.environ)
    env.update(AOC_STORE=str(workdir / "corpora"), COLUMNS="100", OMP_NUM_THREADS="1",
               MKL_NUM_THREADS="1", PYTHONPATH=str(ROOT), TERM="xterm", NO_COLOR="1", AOC_PROGRESS="0",
               PATH=f"{ROOT / '.venv' / 'bin'}{os.pathsep}{env.get('PATH', '')}")
    return env


ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b\][^\x07]*\x07")


def _run(command: str, workdir: Path) -> str:
    """What ``command`` prints on a terminal (a pseudo-terminal, so tables are drawn as a user
    sees them), without colours or cursor movements."""
    proc = subprocess.run(["script", "-qefc", f"stty cols 100 rows 50; {command}", "/dev/null"], cwd=workdir,
                          env=_env(workdir), stdin=subprocess.DEVNULL,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    printed = ANSI.sub("", proc.stdout).replace("\r\n", "\n")
    printed = "\n".join(ln.rsplit("\r", 1)[-1] for ln in printed.split("\n"))
    return printed.replace(str(workdir), "<cwd>")


def refresh(text: str, workdir: Path) -> str:
    """The page's text with every transcript re-run in ``workdir``."""
    lines = text.split("\n")
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("<!-- transcript-setup"):
            j = lines.index("-->", i)
            _run("\n".join(lines[i + 1:j]), workdir)
            out.extend(lines[i:j + 1])
            i = j + 1
            continue
        file_mark = re.match(r"<!-- transcript-file: (\S+) -->", line)
        if file_mark and i + 1 < len(lines) and FENCE.match(lines[i + 1]):
            j = next(k for k in range(i + 2, len(lines)) if FENCE.match(lines[k]))
            (workdir / file_mark.group(1)).write_text("\n".join(lines[i + 2:j]) + "\n")
            out.extend(lines[i:j + 1])
            i = j + 1
            continue
        if line.strip() == "<!-- transcript -->" and i + 1 < len(lines) \
                and lines[i + 1].startswith("```console"):
            j = next(k for k in range(i + 2, len(lines)) if FENCE.match(lines[k]))
            out.extend(lines[i:i + 2])
            for command in [ln[2:] for ln in lines[i + 2:j] if ln.startswith("$ ")]:
                out.append(f"$ {command}")
                printed = _run(command, workdir).rstrip("\n")
                if printed:
                    out.extend(printed.split("\n"))
            out.append(lines[j])
            i = j + 1
            continue
        out.append(line)
        i += 1
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("pages", nargs="*", type=Path,
                        help="pages to refresh (default: README.md and docs/guide/*.md)")
    parser.add_argument("--check", action="store_true",
                        help="change nothing; exit 1 if a page's transcripts differ")
    args = parser.parse_args(argv)
    pages = [p.resolve() for p in args.pages] or [ROOT / "README.md", *sorted((ROOT / "docs" / "guide").glob("*.md"))]
    changed = []
    for page in pages:
        text = page.read_text()
        if "<!-- transcript -->" not in text:
            continue
        with tempfile.TemporaryDirectory(prefix="aoc-transcript-") as tmp:
            new = refresh(text, Path(tmp))
        if new != text:
            changed.append(page)
            if not args.check:
                tmp_path = page.with_name(f".{page.name}.tmp")
                tmp_path.write_text(new)
                tmp_path.replace(page)
        print(f"{page.relative_to(ROOT)}: {'changed' if new != text else 'unchanged'}",
              file=sys.stderr)
    return 1 if (args.check and changed) else 0


if __name__ == "__main__":
    sys.exit(main())
