"""A hostile pass over the public CLI and API: bad input tried as a careless or hostile user would, each try judged.

Every try has what the project promises for it: `refuse` (one line naming what is wrong, a non-zero exit, or an
`MjxPushtError` from the API, and nothing already written lost) or `honour` (it runs and does what the docs say;
a `judge` checks the result where that is not obvious). The verdicts:

- ok: refused in one line, or honoured as documented;
- SILENT: accepted where it should be refused, or honoured with a wrong result (the worst kind);
- TRACEBACK: a crash (a CLI traceback, an exception outside `MjxPushtError` from the API);
- REFUSED: a valid input refused.

The CLI runs in this process (`cli.commands.main`), so 150-odd tries take minutes, not an import each. The
tries themselves are in hostile_cli.py and hostile_api.py; this writes the table:

    python -m benchmarks.hostile_pass --out docs/hostile-pass.md [--only cli|api] [--match TEXT]
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import os
import signal
import sys
import time
import traceback
import warnings
from pathlib import Path


@dataclasses.dataclass
class Try:
    surface: str  # "cli eval", "PushT-v0", "functional", ...
    what: str  # the input, as a user would write it
    run: object  # () -> result; for the CLI, an argv list
    expect: str = "refuse"  # or "honour", or "either" (a refusal in one line and running are both documented answers)
    judge: object = None  # result -> (ok, note) for an honoured try
    after: object = None  # () -> (ok, note): what must hold afterwards (nothing lost)


class Timeout(Exception):
    pass


def _alarm(signum, frame):
    raise Timeout()


def run_cli(argv: list[str]) -> tuple[int, str, str]:
    from mjx_pusht.cli.commands import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as e:  # --help, or argparse's own exit
            code = e.code if isinstance(e.code, int) else 1
        except Timeout:
            raise
        except BaseException:  # noqa: BLE001 - a bug: its traceback is what the user would see
            traceback.print_exc(file=err)
            code = "traceback"
    return code, out.getvalue(), err.getvalue()


def judge_cli(t: Try, timeout: float) -> tuple[str, str]:
    code, out, err = run_cli(t.run)
    lines = [ln for ln in err.splitlines() if ln.strip() and "warning" not in ln.lower() and "%|" not in ln]
    if code == "traceback" or "Traceback (most recent call last)" in err:
        last = [ln for ln in err.splitlines() if ln.strip()][-1]
        return "TRACEBACK", last[:160]
    if code != 0:
        answer = f"exit {code}: " + (lines[-1] if lines else "(no message)")
        if t.expect == "refuse":
            return ("ok" if len(lines) == 1 else "SILENT"), answer + ("" if len(lines) == 1 else f" [{len(lines)} lines]")
        return "REFUSED", answer
    last = [ln for ln in out.splitlines() if ln.strip()]
    answer = "exit 0: " + (last[-2] if len(last) > 1 else last[-1] if last else "(no output)")
    if t.expect == "refuse":
        return "SILENT", answer
    if t.judge is not None:
        ok, note = t.judge((code, out, err))
        return ("ok" if ok else "SILENT"), f"{answer}; {note}"
    return "ok", answer


def judge_api(t: Try) -> tuple[str, str]:
    from mjx_pusht.errors import MjxPushtError

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = t.run()
    except Timeout:
        raise
    except MjxPushtError as e:
        msg = str(e)
        answer = f"{type(e).__name__}: {msg.splitlines()[0] if msg else ''}"
        if t.expect in ("refuse", "either"):
            return ("ok" if msg and "\n" not in msg.strip() else "SILENT"), answer
        return "REFUSED", answer
    except Exception as e:  # noqa: BLE001 - anything else is a crash, whatever its type
        answer = f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"[:200]
        # gymnasium's own checks (its error classes, or raised inside gymnasium: TimeLimit's, the order enforcer's)
        # are the answer every gymnasium env gives: one line, naming the argument
        frames = traceback.extract_tb(e.__traceback__)
        if type(e).__module__.startswith("gymnasium") or (frames and "/gymnasium/" in frames[-1].filename):
            return ("ok" if t.expect in ("refuse", "either") else "REFUSED"), f"{answer} (gymnasium's own check)"
        return "TRACEBACK", answer
    said = "; warned: " + str(caught[0].message).splitlines()[0][:100] if caught else ""
    if t.expect == "either":
        return "ok", f"ran{said}"
    if t.expect == "refuse":
        return "SILENT", f"accepted{said}"
    if t.judge is not None:
        ok, note = t.judge(result)
        return ("ok" if ok else "SILENT"), note + said
    return "ok", f"ran{said}"


def run_all(tries: list[Try], timeout: float) -> list[dict]:
    rows = []
    signal.signal(signal.SIGALRM, _alarm)
    for i, t in enumerate(tries, 1):
        t0 = time.perf_counter()
        signal.alarm(int(timeout))
        try:
            verdict, answer = judge_cli(t, timeout) if t.surface.startswith("cli") else judge_api(t)
            if t.after is not None and verdict == "ok":
                ok, note = t.after()
                if not ok:
                    verdict, answer = "SILENT", f"{answer}; LOST: {note}"
        except Timeout:
            verdict, answer = "SILENT", f"still running after {timeout:.0f} s (nothing checked it up front)"
        finally:
            signal.alarm(0)
        what = " ".join(map(str, t.run)) if t.surface.startswith("cli") else t.what
        rows.append({"n": i, "surface": t.surface, "input": what if t.surface.startswith("cli") else t.what,
                     "expect": t.expect, "answer": answer, "verdict": verdict,
                     "seconds": round(time.perf_counter() - t0, 2)})
        print(f"{i:3d} {verdict:9s} {t.surface:14s} {rows[-1]['input'][:70]:70s} -> {answer[:100]}",
              file=sys.__stdout__, flush=True)
    return rows


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def write_table(rows: list[dict], path: Path, host: str, seconds: float) -> None:
    counts = {v: sum(r["verdict"] == v for r in rows) for v in ("ok", "SILENT", "TRACEBACK", "REFUSED")}
    lines = [
        "# Hostile pass over the CLI and the API",
        "",
        "Bad input tried as a careless or hostile user would, on every public entry point: the flags of every",
        "command, the gymnasium single and vector envs, the gym-pusht drop-in, the functional env and the Brax",
        "adapter. Each try says what the project promises (`refuse`: one line naming what is wrong, a non-zero exit or",
        "an `MjxPushtError`, nothing already written lost; `honour`: it runs and does what the docs say, checked where",
        "that is not obvious). Verdicts: **ok**; **SILENT** (accepted where it should be refused, or a wrong result);",
        "**TRACEBACK** (a crash); **REFUSED** (valid input refused).",
        "",
        f"Rerun: `python -m benchmarks.hostile_pass --out docs/hostile-pass.md` ({len(rows)} tries, "
        f"{seconds / 60:.1f} min on {host}, after building its fixtures; TMP is its temporary folder).",
        "",
        f"**{len(rows)} tries: {counts['ok']} ok, {counts['SILENT']} silent, {counts['TRACEBACK']} tracebacks, "
        f"{counts['REFUSED']} valid inputs refused.**",
        "",
        "| # | entry point | input | promised | answer | verdict |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['n']} | {r['surface']} | `{_cell(r['input'])}` | {r['expect']} | {_cell(r['answer'])} | "
                     f"{r['verdict'] if r['verdict'] == 'ok' else '**' + r['verdict'] + '**'} |")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("docs/hostile-pass.md"))
    p.add_argument("--only", choices=("cli", "api"), default=None)
    p.add_argument("--match", default=None, help="only the tries whose entry point or input contains this")
    p.add_argument("--timeout", type=float, default=120.0, help="seconds a try may run (default 120)")
    p.add_argument("--memory-gb", type=float, default=8.0,
                   help="this process's data limit: a try that would allocate past it fails instead of taking the host "
                        "(0: none)")
    args = p.parse_args(argv)
    import resource
    import tempfile

    if args.memory_gb > 0:  # 0: no limit (inside a test process, which goes on after the pass)
        limit = int(args.memory_gb * 2**30)
        resource.setrlimit(resource.RLIMIT_DATA, (limit, resource.getrlimit(resource.RLIMIT_DATA)[1]))

    from benchmarks import hostile_api, hostile_cli, hostile_exit

    try:
        from mjx_pusht.io.banner import tier
    except ImportError:  # a tree from before the banner moved (to run the pass against another branch)
        from mjx_pusht.cli.banner import tier

    home, args.out = Path.cwd(), args.out.resolve()
    with tempfile.TemporaryDirectory(prefix="hostile-") as d:
        root = Path(d)
        os.chdir(root)  # whatever a try writes by default (outputs/..., MUJOCO_LOG.TXT) lands in the temporary folder
        tries = ([] if args.only == "api" else hostile_cli.tries(root)) + \
                ([] if args.only == "cli" else hostile_api.tries(root) + hostile_exit.tries(root))
        if args.match:
            tries = [t for t in tries if args.match in t.surface or args.match in str(t.what) + str(t.run)]
        t0 = time.perf_counter()
        rows = run_all(tries, args.timeout)
        seconds = time.perf_counter() - t0
        for r in rows:  # the temporary folder's name changes every run: the table says TMP
            r["input"], r["answer"] = (str(r[k]).replace(str(root), "TMP") for k in ("input", "answer"))
        os.chdir(home)
    write_table(rows, args.out, tier(), seconds)
    bad = [r for r in rows if r["verdict"] != "ok"]
    print(f"{len(rows)} tries, {len(bad)} not ok; wrote {args.out}", file=sys.__stdout__)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
