#!/usr/bin/env python3
"""clatch's CPU default extraction vs OpenCV's ORB, same images, same thread count, same run.

    python3 tools/cpu_vs_orb.py [IMAGE ...] [--size WIDTHxHEIGHT] [--threads N] [--rounds 7]
                                [--repeats 5] [--baseline OTHER_BUILD_OF_cpu_extract]

One command: it builds the timer (`cargo build --release -p clatch-cli --example cpu_extract`), then
in each round times, on every image, `ExtractorConfig::default()` (8-level pyramid, 5000 keypoints,
sub-pixel positions, 512-bit descriptors; timed inside the process, decoding excluded) and
`cv2.ORB_create(5000).detectAndCompute` (also 8 levels of factor 1.2), both on THREADS threads
(rayon's pool; `cv2.setNumThreads`), `--repeats` times each after one warm-up call. A figure is the
median over rounds of the per-round medians, in milliseconds; the ratio is clatch / ORB (below 1:
clatch is faster). `--baseline` adds another build of the timer (e.g. one built from an older commit)
to every round, for before/after figures from the same run.

Without IMAGE it uses the embedded photograph (assets/astronaut.png, 512x512) enlarged to
1920x1080. The images are converted to gray (and resized with `--size`) by clatch's decoder once and
written to PNG files that both sides read, so both see the same pixels. Without OpenCV
(`import cv2` fails) the clatch figures are printed and ORB is reported as skipped.
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

from cpu_vs_opencv import cpu_model

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TIMER = os.path.join(ROOT, "target", "release", "examples", "cpu_extract")
OPENCV = "opencv-contrib-python-headless"


def fields(timer, *args):
    out = subprocess.run([timer, *map(str, args)], capture_output=True, text=True, check=True).stdout
    words = out.split()
    return dict(zip(words[::2], words[1::2]))


def time_clatch(timer, image, threads, repeats):
    values = fields(timer, "time", image, threads, repeats)
    return int(values["keypoints"]), float(values["median_ms"])


def time_orb(cv2, gray, repeats):
    orb = cv2.ORB_create(5000)
    keypoints, _ = orb.detectAndCompute(gray, None)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        keypoints, _ = orb.detectAndCompute(gray, None)
        times.append((time.perf_counter() - start) * 1e3)
    return len(keypoints), statistics.median(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("images", nargs="*", help="photographs (default: the embedded one)")
    parser.add_argument("--size", help="resize every image to WIDTHxHEIGHT first")
    parser.add_argument("--threads", type=int, default=os.cpu_count())
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--baseline", help="another build of examples/cpu_extract")
    args = parser.parse_args()

    subprocess.run(
        ["cargo", "build", "--quiet", "--release", "-p", "clatch-cli", "--example", "cpu_extract"],
        cwd=ROOT,
        check=True,
    )
    try:
        import cv2
    except ImportError:
        cv2 = None
        print(f"ORB skipped: OpenCV is not installed (python3 -m pip install {OPENCV})")
    if cv2 is not None:
        cv2.setNumThreads(args.threads)

    sources = args.images or [os.path.join(ROOT, "assets", "astronaut.png")]
    size = args.size or (None if args.images else "1920x1080")
    timers = {"clatch": TIMER}
    if args.baseline:
        timers["baseline"] = args.baseline
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        images = []
        for i, source in enumerate(sources):
            path = os.path.join(tmp, f"{i}.png")
            shape = fields(TIMER, "prepare", source, path, *([size] if size else []))
            name = os.path.basename(source)
            images.append((name, path, f"{shape['width']}x{shape['height']}"))
        grays = {path: cv2.imread(path, cv2.IMREAD_GRAYSCALE) for _, path, _ in images} if cv2 else {}
        rounds = {}
        counts = {}
        for _ in range(args.rounds):
            for _, path, _ in images:
                for who, timer in timers.items():
                    n, ms = time_clatch(timer, path, args.threads, args.repeats)
                    rounds.setdefault((path, who), []).append(ms)
                    counts[(path, who)] = n
                if cv2 is not None:
                    n, ms = time_orb(cv2, grays[path], args.repeats)
                    rounds.setdefault((path, "orb"), []).append(ms)
                    counts[(path, "orb")] = n
    load_after = os.getloadavg()

    opencv = f"OpenCV {cv2.__version__}" if cv2 else "OpenCV absent"
    print(f"CPU: {cpu_model()}, {os.cpu_count()} logical CPUs; {args.threads} threads; {opencv}")
    print(f"load average {load_before[0]:.1f} before, {load_after[0]:.1f} after; {args.rounds} rounds "
          f"x {args.repeats} repeats; ms per image (median of round medians, min..max of round medians)")
    whos = ["orb"] * (cv2 is not None) + list(timers)
    for name, path, shape in images:
        print(f"{name} {shape}:")
        medians = {}
        for who in whos:
            values = rounds[(path, who)]
            medians[who] = statistics.median(values)
            print(f"  {who:<9} {counts[(path, who)]:5d} keypoints {medians[who]:8.2f} ms "
                  f"({min(values):.2f}..{max(values):.2f})")
        if cv2 is not None:
            for who in timers:
                print(f"  {who} / ORB: {medians[who] / medians['orb']:.2f}x")
        if args.baseline:
            print(f"  baseline / clatch: {medians['baseline'] / medians['clatch']:.2f}x")


if __name__ == "__main__":
    sys.exit(main())
