"""Run the README's command examples and check (``--update``: rewrite) the output they show.

An example is a fenced block right after a line ``<!-- example -->``; ``make test`` checks them all
(``tests/test_readme_examples.py``, about two minutes of CPU). Each ``$ `` line of
the block is a command, run by bash in one scratch folder shared by all examples in README order, with this
checkout's ``pdr`` first and ``configs/`` linked in; the lines after it, up to the next ``$ ``, are what it prints (stdout and stderr together).
Speeds (``frames/s``) and the scratch folder's path are masked before comparing. A number with a decimal point
matches within a relative 1e-3 (or one unit of its last shown digit): the least-squares solvers stop at a tolerance,
and another CPU's vector kernels move the 5th-7th digits (a final error 0.80884 m here, 0.8087587 m there); the
text, the integers and every other digit still have to match.

    python docs/readme_examples.py            # check every example; exit 1 and a diff when one drifted
    python docs/readme_examples.py --update   # write what the commands print now into README.md
"""

from __future__ import annotations

import argparse
import dataclasses
import difflib
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MARKER = re.compile(r"^<!-- example -->$")
MASKS = [(re.compile(r"\d+(\.\d+)? frames/s"), "<N> frames/s")]  # speeds vary with the machine's load
DECIMAL = re.compile(r"[-+]?\d+\.\d+(?:[eE][-+]?\d+)?")
REL_TOL = 1e-3  # of a decimal number, shown against printed


@dataclasses.dataclass
class Example:
    """A fenced block: its lines ``first..last`` (the fences excluded) in README.md and its commands with the output
    each shows."""

    first: int
    last: int
    commands: list[tuple[str, list[str]]]


def parse(lines: list[str]) -> list[Example]:
    examples = []
    for i, line in enumerate(lines):
        if not MARKER.match(line.strip()):
            continue
        if i + 1 >= len(lines) or not lines[i + 1].startswith("```"):
            raise SystemExit(f"README.md line {i + 1}: expected a fenced block after the example marker")
        end = next(j for j in range(i + 2, len(lines)) if lines[j].startswith("```"))
        commands: list[tuple[str, list[str]]] = []
        for text in lines[i + 2:end]:
            if text.startswith("$ "):
                commands.append((text[2:], []))
            elif commands:
                commands[-1][1].append(text)
            else:
                raise SystemExit(f"README.md line {i + 3}: expected the block to start with a `$ ` command")
        examples.append(Example(first=i + 2, last=end - 1, commands=commands))
    return examples


def masked(lines: list[str], scratch: Path) -> list[str]:
    out = []
    for line in lines:
        line = line.replace(f"{scratch}/", "").replace(str(scratch), ".")
        for pattern, replacement in MASKS:
            line = pattern.sub(replacement, line)
        out.append(line.rstrip())
    return out


def same_line(shown: str, printed: str) -> bool:
    """The same text and integers, and decimal numbers within :data:`REL_TOL` or one unit of the shown last digit
    (a printed number is rounded: a value another CPU moves by far less than a unit can still round one unit off,
    as the unconverged alternation's last change 0.0208 m against 0.0209 m)."""
    if DECIMAL.sub("#", shown) != DECIMAL.sub("#", printed):
        return False
    for a, b in zip(DECIMAL.findall(shown), DECIMAL.findall(printed)):
        digits = len(a.split(".")[1].split("e")[0].split("E")[0])
        if abs(float(a) - float(b)) > max(REL_TOL * abs(float(a)), 10.0 ** -digits * (1.0 + 1e-9)):
            return False
    return True


def same_output(shown: list[str], printed: list[str]) -> bool:
    return len(shown) == len(printed) and all(same_line(a, b) for a, b in zip(shown, printed))


def run_command(command: str, scratch: Path) -> list[str]:
    """What ``command`` prints (stdout and stderr, in order), run by bash in ``scratch`` with this checkout's pdr."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
               PYTHONUNBUFFERED="1")
    done = subprocess.run(["bash", "-c", command.split("  # ")[0]], cwd=scratch, env=env, text=True,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    return done.stdout.splitlines()


def check(readme: Path = README, *, update: bool = False, scratch: Path | None = None) -> list[str]:
    """Run the examples; return one unified diff per command whose shown output differs (empty: all match). With
    ``update`` the README gets the new output instead."""
    lines = readme.read_text(encoding="utf-8").splitlines()
    diffs: list[str] = []
    replacements: list[tuple[int, int, list[str]]] = []
    with tempfile.TemporaryDirectory(prefix="pdr_readme_") as tmp:
        scratch = Path(scratch or tmp).resolve()
        (scratch / "configs").symlink_to(ROOT / "configs")  # the examples name configs/ as from the repository root
        for example in parse(lines):
            block = []
            for command, shown in example.commands:
                actual = masked(run_command(command, scratch), scratch)
                block += [f"$ {command}", *actual]
                if not same_output(masked(shown, scratch), actual):
                    diffs.append("\n".join(difflib.unified_diff(shown, actual, f"README.md: $ {command}", "printed now",
                                                                lineterm="")))
            replacements.append((example.first, example.last, block))
    if update and diffs:
        for first, last, block in sorted(replacements, reverse=True):
            lines[first:last + 1] = block
        readme.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return diffs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--update", action="store_true", help="write the output printed now into README.md")
    args = parser.parse_args(argv)
    diffs = check(update=args.update)
    for diff in diffs:
        print(diff)
    if diffs and not args.update:
        print(f"{len(diffs)} README example(s) no longer print what README.md shows; "
              "run python docs/readme_examples.py --update", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
