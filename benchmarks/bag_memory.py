"""Benchmark: memory the bag writer holds as a recording grows, one file versus split files.

An MCAP writer keeps one chunk index per finished chunk until it closes, so an unsplit
recording's writer grows for as long as the run lasts (docs/recording.md, "Long runs"). This
measures it with ``tracemalloc`` for a stream like the graph's (``--topics`` channels, a chunk
every ``1 / --chunk-rate`` s of log time) written (a) into one file and (b) into a bag folder split
every ``--split`` s: the growth per chunk and per hour of (a), the peak of (b), their ratio.

Usage (from the repository root):
    .venv/bin/python benchmarks/bag_memory.py [--chunks 30000] [--write-results]
"""

from __future__ import annotations

import argparse
import gc
import platform
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from recorder import RESULTS, update_results_section  # noqa: E402

from contgrasp_ros.bag.writer import BagWriter  # noqa: E402

SECTION = "bag_memory"
PEAK_EVERY = 50  # chunks between the samples that find the peak (a split file holds ~500 at the defaults)


def write_stream(path: Path, args: argparse.Namespace, split_s: float) -> dict[str, Any]:
    """Write ``args.chunks`` chunks; return the traced memory (bytes above the start) over chunks."""
    gc.collect()
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    w = BagWriter(path, max_bag_duration=split_s)
    topics = [f"/t{k}" for k in range(args.topics)]
    for t in topics:
        w.add_topic(t, "std_msgs/msg/String")
    payload = b"\x00\x01\x00\x00" + bytes(args.payload)
    period_ns = int(1e9 / args.chunk_rate)
    samples: list[tuple[int, float]] = []
    peak = 0
    t0 = time.perf_counter()
    for c in range(1, args.chunks + 1):
        log_ns = 10**18 + c * period_ns
        for k, t in enumerate(topics):
            w.write(t, payload, log_ns + k)
        w.flush()  # the recorder's flush timer: finish the open chunk
        if c % PEAK_EVERY == 0 or c % args.report_every == 0:
            gc.collect()
            cur = tracemalloc.get_traced_memory()[0] - base
            peak = max(peak, cur)
            if c % args.report_every == 0:
                samples.append((c, cur))
    files = len(w.files)
    w.close()
    wall = time.perf_counter() - t0
    tracemalloc.stop()
    chunks = np.array([c for c, _ in samples], dtype=float)
    mem = np.array([m for _, m in samples], dtype=float)
    half = len(chunks) // 2
    slope = float(np.polyfit(chunks[half:], mem[half:], 1)[0])  # bytes per chunk, second half
    return {"files": files, "samples": samples, "final": float(mem[-1]), "peak": float(peak),
            "bytes_per_chunk_2nd_half": slope, "wall_s": wall}  # (slope: meaningful for one file only)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--chunks", type=int, default=30000, help="chunks written per case (default 30000)")
    ap.add_argument("--chunk-rate", type=float, default=8.6, help="chunks per second of log time (default 8.6: the soak's median)")
    ap.add_argument("--topics", type=int, default=10, help="channels, one message each per chunk (default 10)")
    ap.add_argument("--payload", type=int, default=64, help="payload bytes per message (default 64)")
    ap.add_argument("--split", type=float, default=60.0, help="max_bag_duration of the split case [s] (default 60)")
    ap.add_argument("--report-every", type=int, default=2000, help="sample the memory every this many chunks (default 2000)")
    ap.add_argument("--write-results", action="store_true", help=f"write/replace the '## {SECTION}' section of {RESULTS.name}")
    args = ap.parse_args(argv)
    if args.chunks < 2 * args.report_every or min(args.chunk_rate, args.topics, args.payload + 1, args.split) <= 0:
        ap.error("need --chunks >= 2 x --report-every and positive --chunk-rate, --topics, --split")
    out: list[str] = []

    def say(line: str = "") -> None:
        print(line, flush=True)
        out.append(line)

    hours = args.chunks / args.chunk_rate / 3600
    say(f"python {platform.python_version()}, {args.chunks} chunks x {args.topics} topics ({args.payload} B payloads), "
        f"{args.chunk_rate} chunks/s of log time = {hours:.2f} h of recording; split case: max_bag_duration {args.split:g} s")
    with tempfile.TemporaryDirectory() as tmp:
        one = write_stream(Path(tmp) / "one", args, 0.0)
        split = write_stream(Path(tmp) / "split", args, args.split)
    say("| chunks | log time [h] | (a) one file [MB] | (b) split [MB] |")
    say("|---|---|---|---|")
    for (c, a), (_, b) in zip(one["samples"], split["samples"], strict=True):
        say(f"| {c} | {c / args.chunk_rate / 3600:.2f} | {a / 1e6:.2f} | {b / 1e6:.2f} |")
    per_h = args.chunk_rate * 3600 / 1e6
    say(f"(a) one file: {one['files']} file, {one['bytes_per_chunk_2nd_half']:.0f} B per chunk over the second half "
        f"= {one['bytes_per_chunk_2nd_half'] * per_h:.1f} MB/h at {args.chunk_rate} chunks/s; final {one['final'] / 1e6:.2f} MB "
        f"(wall {one['wall_s']:.1f} s)")
    say(f"(b) split:    {split['files']} files; memory rises within each file and falls at each split (sawtooth), "
        f"peak {split['peak'] / 1e6:.2f} MB over the whole run (sampled every {PEAK_EVERY} chunks) (wall {split['wall_s']:.1f} s)")
    say(f"ratio (a) final / (b) peak = {one['final'] / max(split['peak'], 1.0):.0f}x after {hours:.2f} h; "
        f"(a) grows without bound, (b) stays below its peak")
    if args.write_results:
        cmd = " ".join(["python", "benchmarks/bag_memory.py", *(sys.argv[1:] if argv is None else argv)])
        body = (f"Command (from the repository root, one process, both cases in the same run):\n\n    .venv/bin/{cmd}\n\n"
                "Memory held by `BagWriter` (tracemalloc, Python allocations) while a recording grows: one file versus a "
                "bag folder split by `max_bag_duration` (docs/recording.md, long runs).\n\n```\n" + "\n".join(out) + "\n```\n")
        update_results_section(RESULTS, SECTION, body)
        print(f"wrote section '## {SECTION}' of {RESULTS}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
