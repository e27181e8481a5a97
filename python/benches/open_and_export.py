"""Benchmark: a 60 s run at 20 kS/s × 5 channels into numpy, to Parquet, and the file sizes.

    python python/benches/open_and_export.py [--run RUN_FOLDER] [--keep DIR]

Without --run it takes the run first: a virtual rig (`tribo rig --virtual --speed inf`) and
`tribo run --load 0 --rate 20000 --max-duration 60` (the apparatus alone: its slow decay lasts
the whole 60 s), about half a minute. Uses `$TRIBO_BIN`, else target/release/tribo, else
target/debug/tribo. Prints the times (best of 5) and the sizes of the frame log, the run's CSV
and the Parquet file. Measure with a release wheel (`cargo xtask wheel --release`): the dev
profile does not optimise the workspace's own crates.
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import tribo

REPO = Path(__file__).resolve().parents[2]


def tribo_bin() -> str:
    if os.environ.get("TRIBO_BIN"):
        return os.environ["TRIBO_BIN"]
    for p in ("release", "debug"):
        b = REPO / "target" / p / "tribo"
        if b.exists():
            return str(b)
    sys.exit("no tribo binary: `cargo build --release -p tribo`, or set TRIBO_BIN")


def take_run(store: Path) -> Path:
    exe = tribo_bin()
    rig = subprocess.Popen(
        [exe, "rig", "--virtual", "--listen", "127.0.0.1:0", "--speed", "inf"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert rig.stdout is not None
        line = rig.stdout.readline()
        m = re.search(r"tcp://\S+", line)
        if not m:
            sys.exit(f"the virtual rig did not say its address: {line!r}")
        subprocess.run(
            [exe, "-q", "run", "--port", m.group(0), "--load", "0", "--rate", "20000",
             "--max-duration", "60", "--store", str(store)],
            check=True,
            stdout=subprocess.DEVNULL,
        )
    finally:
        rig.terminate()
        rig.wait()
    return next(p for p in store.iterdir() if p.is_dir())


def best(f, n=5):
    times = []
    out = None
    for _ in range(n):
        t0 = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", type=Path, help="an existing run folder (else one is taken)")
    ap.add_argument("--keep", type=Path, help="take the run into this store and keep it")
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="tribo-bench-"))
    run_dir = a.run or take_run(a.keep or tmp / "runs")
    t_open, run = best(lambda: tribo.open_run(run_dir))
    chans = [n for n in ("x", "v", "ft", "temp", "ecr") if getattr(run, n) is not None]
    print(f"run        {run_dir}")
    print(f"samples    {len(run)} ({run.t[-1] - run.t[0]:.1f} s at {run.sample_rate_hz:.0f} S/s), "
          f"channels {', '.join(chans)}")
    print(f"open_run   {t_open:.3f} s into numpy (goal ≤ 0.3 s)")
    t_pd, _ = best(run.to_pandas)
    print(f"to_pandas  {t_pd:.3f} s")
    pq = tmp / "run.parquet"
    t_pq, _ = best(lambda: tribo.export_parquet(run_dir, pq))
    print(f"parquet    {t_pq:.3f} s (tribo.export_parquet)")
    t0 = time.perf_counter()
    subprocess.run([tribo_bin(), "-q", "export", str(run_dir), "--format", "parquet", "-o", str(pq)], check=True)
    print(f"           {time.perf_counter() - t0:.3f} s (`tribo export --format parquet`, the process included)")
    csv = run_dir / "samples.csv"
    if not csv.exists():
        subprocess.run([tribo_bin(), "-q", "export", str(run_dir), "--format", "csv", "-o", str(csv)], check=True)
    sizes = {
        "frames.log": (run_dir / "frames.log").stat().st_size,
        "CSV (samples.csv)": csv.stat().st_size,
        "Parquet": pq.stat().st_size,
    }
    for k, v in sizes.items():
        print(f"size       {k:<18} {v / 1e6:8.1f} MB  ({v / sizes['CSV (samples.csv)']:.1%} of the CSV)")
    try:
        import pandas as pd

        t_read, _ = best(lambda: pd.read_parquet(pq), 3)
        print(f"read back  {t_read:.3f} s (pandas.read_parquet)")
    except ImportError:
        pass


if __name__ == "__main__":
    main()
