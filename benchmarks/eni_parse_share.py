"""How much of a whole `lolacli sdo read` the ENI parse is: the bound on what a cache of
parsed ENI models could gain on a figure a user sees.

    python benchmarks/eni_parse_share.py                 # LOLA + the three largest corpus ENIs
    python benchmarks/eni_parse_share.py --runs 11 --eni path/to/eni.xml

Per ENI: the parse in process (``lolacli.eni.parser.parse_eni``, median of ``--runs``),
the unpickling of the parsed model (what a pickle cache costs instead), and the whole
command ``python -m lolacli sdo read 1 0x1000 [--eni F]`` (the chain emulated in process,
median of ``--runs``, wall time). ``best cache gain`` = whole / (whole - parse +
unpickle): what the whole command would gain if the parse cost only the unpickling.
Issue 24 keeps a second implementation only at 2x or more; the pickle cache this
bounds (``lolacli/eni_cache.py``) measured 0.88-1.11x on the whole command, cache warm
against off, and was removed.
"""

from __future__ import annotations

import argparse
import os
import pickle
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from lolacli.eni.parser import parse_eni  # noqa: E402


def _median_s(fn, runs: int) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def whole_command(eni: Path | None) -> float:
    cmd = [sys.executable, "-m", "lolacli", "sdo", "read", "1", "0x1000"]
    cmd += ["--eni", str(eni)] if eni is not None else []
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    t = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, cwd=ROOT)
    dt = time.perf_counter() - t
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}: exit {done.returncode}: {done.stderr.decode()}")
    return dt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--eni", type=Path, action="append", default=None)
    args = ap.parse_args()
    corpus = Path(os.environ.get("LOLACLI_CORPUS", ROOT.parent / "shared" / "corpus"))
    lola = ROOT / "lolacli" / "eni_examples" / "lola.xml"
    if args.eni:
        enis: list[Path | None] = list(args.eni)
    else:
        largest = sorted((corpus / "eni").glob("*.xml"), key=lambda p: -p.stat().st_size)[:3]
        enis = [None, *largest]
    print(f"{'ENI':44} {'kB':>5} {'parse':>8} {'unpickle':>9} {'whole':>8} {'best gain':>9}")
    for eni in enis:
        path = eni or lola
        data = path.read_bytes()
        model = parse_eni(data, source=str(path))
        blob = pickle.dumps(model, protocol=pickle.HIGHEST_PROTOCOL)
        parse = _median_s(lambda d=data, p=path: parse_eni(d, source=str(p)), args.runs)
        unpickle = _median_s(lambda b=blob: pickle.loads(b), args.runs)
        whole_command(eni)  # bytecode and page cache warm
        whole = statistics.median(whole_command(eni) for _ in range(args.runs))
        gain = whole / (whole - parse + unpickle)
        print(f"{path.name[:44]:44} {len(data) / 1e3:5.0f} {parse * 1e3:6.1f}ms "
              f"{unpickle * 1e3:7.1f}ms {whole * 1e3:6.0f}ms {gain:8.2f}x")


if __name__ == "__main__":
    main()
