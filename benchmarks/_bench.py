"""Shared by the benchmark scripts: best-of timing, the stamp of a run (date, commit,
machine) and one table writer for the terminal and the docs.

Every script prints its tables through :class:`Report`. With ``--markdown`` (added by
:func:`add_markdown_option`) the same rows are also written as a Markdown file, by
default ``docs/benchmarks/generated/<script>.md``, which a benchmark page includes
(``--8<-- "docs/benchmarks/generated/<script>.md"``), stamped with the date, the commit
(``+dirty`` when the work tree has uncommitted changes) and the machine. Plots go beside
it as PNG files.

Tables measured earlier by a script that is too slow to rerun for the docs are kept as
records (``benchmarks/records/<name>.json``: the rows, the date, commit and machine they
were measured on, as printed then) and written through the same writer:

    python benchmarks/_bench.py benchmarks/records/NAME.json [--markdown [PATH]]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import shlex
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
GENERATED = REPO / "docs" / "benchmarks" / "generated"
# the pages that include the generated files (image links are relative to them)
PAGES = REPO / "docs" / "benchmarks"
# written files and prose are not code: a dirty stamp names changes to the code only
# (git pathspecs; a page or the changelog edited while a benchmark runs changes no number)
_NOT_CODE = (":(exclude)docs/benchmarks/generated", ":(exclude,glob)**/*.md")


def best_of(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    """(fastest seconds, last result) over ``repeat`` calls."""
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


# ---------------------------------------------------------------------------------------
# the stamp of a run


def git_commit(repo: Path = REPO) -> str:
    """Short hash of HEAD, ``+dirty`` when tracked or untracked code differs from it;
    ``unknown`` outside a git checkout."""
    head = subprocess.run(["git", "-C", str(repo), "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True)
    if head.returncode != 0:
        return "unknown"
    status = subprocess.run(
        ["git", "-C", str(repo), "status", "--porcelain", "--", ".", *_NOT_CODE],
        capture_output=True, text=True)
    dirty = status.returncode != 0 or bool(status.stdout.strip())
    return head.stdout.strip() + ("+dirty" if dirty else "")


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def _ram_gib() -> float | None:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    except (ValueError, OSError, AttributeError):
        return None


def _os_name() -> str:
    try:
        for line in Path("/etc/os-release").read_text().splitlines():
            if line.startswith("PRETTY_NAME="):
                return line.split("=", 1)[1].strip().strip('"')
    except OSError:
        pass
    return f"{platform.system()} {platform.release()}"


def machine() -> str:
    """CPU model, cores, RAM, OS, Python and numpy versions, on one line."""
    import numpy as np

    ram = _ram_gib()
    parts = [_cpu_model(), f"{os.cpu_count()} cores",
             "RAM unknown" if ram is None else f"{ram:.1f} GiB RAM", _os_name(),
             f"Python {platform.python_version()}", f"numpy {np.__version__}"]
    return ", ".join(parts)


@dataclass
class Stamp:
    """When, at which commit and on which machine the numbers were measured."""

    date: str
    commit: str
    machine: str
    load: str = ""
    recorded: str = ""  # non-empty: the rows were measured earlier; says how they were kept

    @classmethod
    def now(cls) -> Stamp:
        try:
            load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
        except OSError:
            load = ""
        date = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
        return cls(date=date, commit=git_commit(), machine=machine(), load=load)

    def lines(self) -> list[str]:
        """``Date: ...``, ``Commit: ...``, ``Machine: ...`` (and the load average)."""
        out = [f"Date: {self.date}", f"Commit: {self.commit}", f"Machine: {self.machine}"]
        if self.load:
            out.append(f"Load average at start (1, 5, 15 min): {self.load}")
        if self.recorded:
            out.append(f"Recorded: {self.recorded}")
        return out


# ---------------------------------------------------------------------------------------
# tables

_NUMBER = re.compile(r"^[-+]?(\d[\d ]*\.?\d*|\.\d+)([eE][-+]?\d+)?\s*[x%*]?$")


def _numeric(column: Sequence[str]) -> bool:
    cells = [c.strip() for c in column if c.strip() not in ("", "-")]
    return bool(cells) and all(_NUMBER.match(c) for c in cells)


def _md_text(text: str) -> str:
    """Plain text for Markdown: ``*`` stays a star (``lambert+ggx*2``), not emphasis."""
    return text.replace("*", r"\*")


def _md_cell(text: str) -> str:
    return _md_text(text).replace("|", r"\|").replace("\n", " ") or " "


@dataclass
class Table:
    """A title, a header and rows of strings; ``note`` is printed under the table."""

    title: str
    header: list[str]
    rows: list[list[str]]
    note: str = ""

    def __post_init__(self) -> None:
        self.header = [str(h) for h in self.header]
        self.rows = [[str(c) for c in r] for r in self.rows]
        for r in self.rows:
            if len(r) != len(self.header):
                raise ValueError(f"{self.title!r}: a row has {len(r)} cells for "
                                 f"{len(self.header)} columns: {r}")

    def terminal(self) -> str:
        """Right-aligned columns under the title, the note below."""
        widths = [max([len(h), *(len(r[i]) for r in self.rows)])
                  for i, h in enumerate(self.header)]
        lines = [self.title,
                 "  ".join(h.rjust(w) for h, w in zip(self.header, widths, strict=True))]
        lines += ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True))
                  for r in self.rows]
        if self.note:
            lines.append(self.note)
        return "\n".join(lines)

    def markdown(self) -> str:
        """The title in bold, a pipe table (numeric columns right-aligned), the note."""
        align = ["---:" if _numeric([r[i] for r in self.rows]) else "---"
                 for i in range(len(self.header))]
        lines = [f"**{_md_text(self.title)}**", "",
                 "| " + " | ".join(_md_cell(h) for h in self.header) + " |",
                 "| " + " | ".join(align) + " |"]
        lines += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in self.rows]
        if self.note:
            lines += ["", self.note]
        return "\n".join(lines)


def table(title: str, header: list[str], rows: list[list[str]]) -> None:
    """Print one table (terminal only); scripts with ``--markdown`` use :class:`Report`."""
    print("\n" + Table(title, header, rows).terminal())


# ---------------------------------------------------------------------------------------
# a run's report


@dataclass
class Report:
    """What a script prints, kept for the docs: tables, notes and plots in order.

    ``markdown``: where :meth:`write` puts the Markdown file (None: the terminal only).
    ``command``: how the numbers were made (shown in the stamp)."""

    script: str
    markdown: Path | None = None
    command: str = ""
    stamp: Stamp = field(default_factory=Stamp.now)
    parts: list[str] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    quiet: bool = False

    def _say(self, text: str) -> None:
        if not self.quiet:
            print(text, flush=True)

    def table(self, title: str, header: list[str], rows: list[list[str]],
              note: str = "") -> Table:
        """Print a table and keep it for the Markdown file."""
        t = Table(title, header, rows, note)
        self.tables.append(t)
        self.parts.append(t.markdown())
        self._say("\n" + t.terminal())
        return t

    def note(self, text: str) -> None:
        """A paragraph under the tables (printed too)."""
        self.parts.append(text)
        self._say(text)

    def stem(self, default: str) -> str:
        """A figure's file name: the Markdown file's, so that a run written to another
        file (other fits, other options) keeps the default run's pictures; ``default``
        without one."""
        return default if self.markdown is None else self.markdown.stem

    def figure(self, fig: Any, stem: str, caption: str, fmt: str = "png") -> Path | None:
        """Save a matplotlib figure as ``<stem>.png`` beside the Markdown file and link it
        there; without ``--markdown`` nothing is saved. ``fmt="jpg"``: a JPEG (quality
        90) for pictures of noisy renders, which PNG stores at several times the size."""
        if self.markdown is None:
            return None
        if fmt not in ("png", "jpg"):
            raise ValueError(f"figure format must be png or jpg, got {fmt!r}")
        png = self.markdown.parent / f"{stem}.{fmt}"
        png.parent.mkdir(parents=True, exist_ok=True)
        if fmt == "png":
            fig.savefig(png, dpi=110, bbox_inches="tight", metadata={"Software": None})
        else:
            fig.savefig(png, dpi=110, bbox_inches="tight", pil_kwargs={"quality": 90})
        try:
            link = png.resolve().relative_to(PAGES.resolve()).as_posix()
        except ValueError:
            link = png.name
        self.parts.append(f"![{caption}]({link})")
        return png

    def text(self) -> str:
        """The Markdown: a stamp block, then the tables, notes and plots."""
        s = self.stamp
        origin = (f"Rows measured by `benchmarks/{self.script}`, kept as a record and "
                  f"written by `python benchmarks/_bench.py`" if s.recorded else
                  f"Written by `benchmarks/{self.script}`")
        title = f"Measured {s.date[:10]} at {s.commit}" + (" (kept as a record)"
                                                            if s.recorded else "")
        stamp = [*s.lines(), *([f"Command: `{self.command}`"] if self.command else [])]
        head = [f"<!-- {origin.replace('`', '')}; do not edit by hand -->",
                f'!!! info "{title}"', f"    {origin}.", "",
                *(f"    - {line}" for line in stamp)]
        return "\n".join(head) + "\n\n" + "\n\n".join(self.parts) + "\n"

    def write(self) -> Path | None:
        """Write the Markdown file (if asked for); returns its path."""
        if self.markdown is None:
            return None
        self.markdown.parent.mkdir(parents=True, exist_ok=True)
        self.markdown.write_text(self.text())
        print(f"\nwrote {self.markdown}", file=sys.stderr)
        return self.markdown


def add_markdown_option(ap: argparse.ArgumentParser) -> None:
    """``--markdown [PATH]``: also write the tables (and plots) for the docs."""
    ap.add_argument("--markdown", nargs="?", const="", default=None, metavar="PATH",
                    help="also write the tables as Markdown for the docs (default path: "
                         "docs/benchmarks/generated/<script>.md), stamped with the date, "
                         "commit and machine")


def report(args: argparse.Namespace, script_file: str, *,
           name: str | None = None) -> Report:
    """A :class:`Report` for ``script_file`` from the parsed ``--markdown`` option.

    ``name`` replaces the script's stem in the default file name (a script that writes
    different tables for different settings)."""
    script = Path(script_file).name
    path: Path | None = None
    md = getattr(args, "markdown", None)
    if md is not None:
        path = Path(md) if md else GENERATED / f"{name or Path(script).stem}.md"
    command = " ".join(["python", f"benchmarks/{script}", *map(shlex.quote, sys.argv[1:])])
    return Report(script=script, markdown=path, command=command)


# ---------------------------------------------------------------------------------------
# a rational fit against analytic models, per channel (compare_models, bench_holdout)


class ModelComparison:
    """Rows of per-channel errors: the rational fit against the better of several
    analytic models for each metric (``models[spec][channel][metric]``), and whether
    the rational fit wins all of them. Each cell: ``rational / model (model/rational x)``
    (above 1x: the rational fit is better)."""

    def __init__(self, metrics: Sequence[str], labels: dict[str, str] | None = None) -> None:
        self.metrics = list(metrics)
        self.labels = labels or {}
        self.rows: list[list[str]] = []
        self.ratios: list[tuple[str, list[float]]] = []  # (material channel, per metric)
        self.wins = self.total = 0

    def header(self, size: str, seconds: str) -> list[str]:
        return ["material", "ch", size,
                *(f"{self.labels.get(k, k)} rat / model" for k in self.metrics),
                "wins all", seconds]

    def add(self, material: str, channel: str, size: str, rational: dict[str, float],
            models: dict[str, dict[str, dict[str, float]]], seconds: float) -> bool:
        """One channel's row; returns whether the rational fit wins every metric."""
        cells, won, ratios = [], True, []
        for k in self.metrics:
            best = min(models, key=lambda s, k=k: models[s][channel][k])
            b, r = models[best][channel][k], rational[k]
            won &= bool(r < b)
            ratios.append(b / r if r > 0 else float("inf"))
            cells.append(f"{r:.4g} / {b:.4g} ({ratios[-1]:.2f}x)")
        self.rows.append([material, channel, size, *cells, "yes" if won else "no",
                          f"{seconds:.1f}"])
        self.ratios.append((f"{material} {channel}", ratios))
        self.wins += won
        self.total += 1
        return won

    def add_missing(self, material: str, channel: str, size: str, why: str,
                    seconds: float) -> None:
        """A channel with nothing to compare (no fit, or not every fold verified)."""
        self.rows.append([material, channel, size, *([why] + ["-"] * (len(self.metrics) - 1)),
                          "no", f"{seconds:.1f}"])
        self.total += 1

    def figure(self) -> Any:
        """Bars of model / rational per channel and metric (log scale; above 1: the
        rational fit is better), or None with no row."""
        if not self.ratios:
            return None
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import numpy as np

        fig, ax = plt.subplots(figsize=(max(6.0, 0.42 * len(self.ratios) + 1.5), 3.6))
        x = np.arange(len(self.ratios))
        w = 0.8 / len(self.metrics)
        for i, k in enumerate(self.metrics):
            ax.bar(x + (i - (len(self.metrics) - 1) / 2) * w,
                   [r[i] for _, r in self.ratios], w, label=self.labels.get(k, k))
        ax.axhline(1.0, color="black", lw=0.8)
        ax.set_yscale("log")
        # 1 (as good as the model) always inside, with room above and below
        finite = [v for _, r in self.ratios for v in r if np.isfinite(v) and v > 0] + [1.0]
        ax.set_ylim(min(finite) / 1.5, max(finite) * 1.5)
        ax.set_xticks(x, [n for n, _ in self.ratios], rotation=60, ha="right", fontsize=8)
        ax.set_ylabel("better model's error / rational's")
        ax.legend(fontsize=8)
        ax.grid(axis="y", which="both", alpha=0.3)
        fig.tight_layout()
        return fig

    def write_to(self, rep: Report, *, title: str, size: str, seconds: str, what: str,
                 legend: str, plot: str, caption: str) -> None:
        """The table and its bar plot (file ``plot``, ``caption``) into ``rep``, with the
        one sentence that counts the channels the rational fit wins: ``what`` says which
        errors ("The default rational fit", "Held out, the default rational fit"),
        ``legend`` the table's own columns."""
        rep.table(title, self.header(size, seconds), self.rows,
                  note=f"{what} beats the better model on all of {', '.join(self.metrics)} "
                       f"in {self.wins} of {self.total} channels. Each cell: rational / better "
                       f"model (model / rational); {legend}")
        fig = self.figure()
        if fig is not None:
            rep.figure(fig, plot, caption)


# ---------------------------------------------------------------------------------------
# records: rows measured earlier, written through the same writer


def record_report(record: dict[str, Any], markdown: Path | None) -> Report:
    """A :class:`Report` of a record (see the module's docstring for its keys)."""
    stamp = Stamp(date=record["date"], commit=record["commit"], machine=record["machine"],
                  load=record.get("load", ""), recorded=record["recorded"])
    rep = Report(script=record["script"], markdown=markdown,
                 command=record.get("command", ""), stamp=stamp)
    for t in record["tables"]:
        rep.table(t["title"], t["header"], t["rows"], t.get("note", ""))
    for text in record.get("notes", []):
        rep.note(text)
    return rep


def main() -> None:
    ap = argparse.ArgumentParser(description="Write a recorded benchmark table.")
    ap.add_argument("record", type=Path, help="benchmarks/records/NAME.json")
    add_markdown_option(ap)
    args = ap.parse_args()
    record = json.loads(args.record.read_text())
    path = None
    if args.markdown is not None:
        path = Path(args.markdown) if args.markdown else GENERATED / f"{args.record.stem}.md"
    record_report(record, path).write()


if __name__ == "__main__":
    main()
