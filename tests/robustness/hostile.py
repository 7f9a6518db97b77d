"""Run the hostile-input corpus over every command and print the failures grouped by kind.

    python -m tests.robustness.hostile            # the small corpus (the one tests/robustness/test_corpus.py runs)
    python -m tests.robustness.hostile --full     # several hundred inputs x the commands
    python -m tests.robustness.hostile --full -j 2 --report failures.txt --filter sqlite

Each run is judged by :func:`tests.robustness.runner.judge` against its case's
expectation (see :mod:`tests.robustness.corpus`). The table lists every
failure kind with its runs (case, command, expectation, first and last line of
stderr); the last line totals runs, tracebacks, kills, timeouts, data-changed
and expectation-failed. Exit status 1 when anything failed.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from tests.robustness.corpus import Case, Run, build_corpus, summary
from tests.robustness.runner import DEFAULT_MEM_LIMIT, KINDS, Failure, Outcome, judge, run_many

EXPECTATION_KINDS = ("accepted-bad-input", "silent-on-bad-input", "refused-valid-input", "error-not-one-line",
                     "error-names-no-file", "unexpected-exit-code")


def signature(text: str) -> str:
    """``text`` with paths, numbers and quoted values blanked, to group alike failures."""
    text = re.sub(r"(/[\w.\-+^%]+)+/?", "<path>", text)
    text = re.sub(r"0x[0-9a-fA-F]+", "<n>", text)
    text = re.sub(r"-?\d+(\.\d+)?(e[+-]?\d+)?", "<n>", text)
    text = re.sub(r"'[^']*'", "'…'", text)
    return text[:160]


def _short(line: str, width: int = 220) -> str:
    return line if len(line) <= width else line[: width - 1] + "…"


def run_corpus(cases: list[Case], workers: int, timeout_s: float, mem_limit: int, progress: bool = True
               ) -> list[tuple[Case, Run, Outcome, list[Failure]]]:
    todo = [(case, run) for case in cases if not case.skip for run in case.runs]
    jobs = [run.job(timeout_s, mem_limit) for _, run in todo]
    done = [0]
    t0 = time.monotonic()

    def on_done(index: int, outcome: Outcome) -> None:
        done[0] += 1
        if progress and (done[0] % 25 == 0 or done[0] == len(jobs)):
            print(f"  {done[0]}/{len(jobs)} runs, {time.monotonic() - t0:.0f} s", file=sys.stderr, flush=True)

    outcomes = run_many(jobs, workers=workers, on_done=on_done)
    return [(case, run, outcome, judge(outcome, run.expect)) for (case, run), outcome in zip(todo, outcomes)]


def report(results: list[tuple[Case, Run, Outcome, list[Failure]]], skipped: list[Case], verbose: bool = True) -> str:
    by_kind: dict[str, list[tuple[Case, Run, Outcome, Failure]]] = defaultdict(list)
    for case, run, outcome, failures in results:
        for failure in failures:
            by_kind[failure.kind].append((case, run, outcome, failure))
    lines = []
    for kind in KINDS:
        items = by_kind.get(kind, [])
        if not items:
            continue
        lines.append("")
        lines.append(f"== {kind}: {len(items)} run(s)")
        groups: dict[str, list] = defaultdict(list)
        for item in items:
            case, run, outcome, failure = item
            if kind in ("traceback", "data-changed"):
                key = signature(failure.detail)
            elif outcome.error_lines or outcome.lines:
                key = signature(outcome.error_lines[0] if outcome.error_lines else outcome.stderr_first)
            else:
                key = f"(nothing on stderr) {case.group} :: {run.command}"
            groups[key].append(item)
        for key, group in sorted(groups.items(), key=lambda kv: -len(kv[1])):
            lines.append(f"  -- {len(group)} x {key}")
            for case, run, outcome, failure in group if verbose else group[:3]:
                lines.append(f"     {case.name} :: {run.command} (expect {run.expect}; {outcome.describe().split(';')[0]})")
                lines.append(f"        $ bagtools {' '.join(run.argv)}")
                lines.append(f"        detail: {_short(failure.detail)}")
                if outcome.lines:
                    lines.append(f"        stderr first: {_short(outcome.stderr_first)}")
                    if len(outcome.lines) > 1:
                        lines.append(f"        stderr last:  {_short(outcome.stderr_last)}")
            if not verbose and len(group) > 3:
                lines.append(f"     ... and {len(group) - 3} more")
    stray = [(c, r, o) for c, r, o, f in results if o.exit_code == 0 and o.other_lines]
    if stray:
        lines.append("")
        lines.append(f"== note (not counted): {len(stray)} successful run(s) printed non-bagtools lines on stderr")
        sigs: dict[str, list] = defaultdict(list)
        for c, r, o in stray:
            sigs[signature(o.other_lines[0])].append((c, r, o))
        for key, group in sorted(sigs.items(), key=lambda kv: -len(kv[1])):
            lines.append(f"  -- {len(group)} x {key}   e.g. {group[0][0].name} :: {group[0][1].command}")
    n = len(results)
    failed_runs = sum(1 for *_, f in results if f)
    count = {k: len(v) for k, v in by_kind.items()}
    expectation_failed = sum(count.get(k, 0) for k in EXPECTATION_KINDS)
    seconds = sum(o.seconds for _, _, o, _ in results)
    lines.append("")
    if skipped:
        lines.append(f"skipped {len(skipped)} input(s): " + "; ".join(f"{c.name} ({c.skip})" for c in skipped))
    lines.append(f"TOTAL: {n} runs ({failed_runs} failed, {seconds:.0f} s of child time): "
                 f"{count.get('traceback', 0)} tracebacks, {count.get('killed', 0)} kills, "
                 f"{count.get('timeout', 0)} timeouts, {count.get('data-changed', 0)} data-changed, "
                 f"{expectation_failed} expectation-failed")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.robustness.hostile", description=__doc__.split("\n")[0])
    parser.add_argument("--full", action="store_true", help="the full corpus (default: the small one)")
    parser.add_argument("-j", "--jobs", type=int, default=1, help="runs at once (default 1; the machine is shared)")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds per run before it is killed")
    parser.add_argument("--mem", type=float, default=DEFAULT_MEM_LIMIT / 2**30, help="GiB of address space a run may add to the warm parent's")
    parser.add_argument("--dest", type=Path, help="where to write the corpus (default: a temporary directory)")
    parser.add_argument("--filter", help="only cases whose name contains this")
    parser.add_argument("--group", help="only cases of this group (mcap-file, sqlite3, ros1, message-content, ...)")
    parser.add_argument("--report", type=Path, help="also write the full report to this file")
    parser.add_argument("--json", type=Path, help="write every run's outcome as JSON lines")
    parser.add_argument("--brief", action="store_true", help="list at most 3 runs per failure group")
    args = parser.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix="bagtools-hostile-") as tmp:
        dest = args.dest or Path(tmp)
        t0 = time.monotonic()
        cases = build_corpus(dest, "full" if args.full else "small")
        if args.filter:
            cases = [c for c in cases if args.filter in c.name]
        if args.group:
            cases = [c for c in cases if c.group == args.group]
        skipped = [c for c in cases if c.skip]
        print(f"corpus: {summary(cases)}; built in {time.monotonic() - t0:.1f} s under {dest}", file=sys.stderr)
        t1 = time.monotonic()
        results = run_corpus(cases, args.jobs, args.timeout, int(args.mem * 2**30))
        wall = time.monotonic() - t1
        text = report(results, skipped, verbose=not args.brief)
        text += f"\nwall time: {wall:.0f} s for the runs ({args.jobs} at once), {time.monotonic() - t0:.0f} s in all"
        print(text)
        if args.report:
            args.report.write_text(report(results, skipped, verbose=True) + "\n")
        if args.json:
            with args.json.open("w") as f:
                for case, run, outcome, failures in results:
                    f.write(json.dumps({
                        "case": case.name, "group": case.group, "command": run.command, "argv": run.argv,
                        "expect": run.expect, "exit_code": outcome.exit_code, "signal": outcome.signal,
                        "timed_out": outcome.timed_out, "seconds": round(outcome.seconds, 3),
                        "stderr": outcome.stderr[-4000:], "out_diff": outcome.out_diff,
                        "failures": [[f.kind, f.detail] for f in failures]}) + "\n")
    return 1 if any(f for *_, f in results) else 0


if __name__ == "__main__":
    sys.exit(main())
