#!/usr/bin/env python3
"""clatch's CPU describe vs OpenCV contrib's LATCH, same image, same keypoints, same run.

    python3 -m pip install opencv-contrib-python-headless==5.0.0.93   # numpy comes with it
    cargo build --release --example cpu_describe
    python3 tools/cpu_vs_opencv.py [--rounds 7] [--repeats 5] [--keypoints 5000] [--threshold 6]
                                   [--baseline OTHER_BUILD_OF_cpu_describe]

The image is assets/astronaut.png (512x512 gray) resized to 1024x768 (bilinear), as in the project's
LATCH reference measurements. clatch's detector (threshold lowered to reach the keypoint count) picks the
keypoints; they are written to a file and fed to both: clatch via examples/cpu_describe (timed inside
the process, image loading excluded), OpenCV via `LATCH_create(64, True, 3).compute` (its 3x3 blur
and border filter included: both are part of its describe call). All of clatch's keypoints pass
OpenCV's 27-pixel border filter (clatch's margin is 48), so both describe the same keypoints.

Each round times OpenCV (1 thread: its LATCH has no threading), clatch on 1 thread and clatch on all
threads, `--repeats` times each; the figures are medians over rounds of the per-round medians, in
microseconds per descriptor. Ratios > 1 mean clatch is faster. `--baseline` adds, in each round, the
1-thread time of another build of the timer (e.g. one built from an older commit), for before/after
figures from the same run.
"""

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "target", "release", "examples", "cpu_describe")
OPENCV_PIN = "opencv-contrib-python-headless==5.0.0.93"


def cpu_model():
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
        for line in out.splitlines():
            if line.startswith("Model name:"):
                return line.split(":", 1)[1].strip()
    except (OSError, subprocess.CalledProcessError):
        pass
    return platform.processor() or "unknown"


def clatch(args, timer=EXAMPLE):
    out = subprocess.run([timer, *map(str, args)], capture_output=True, text=True, check=True)
    return out.stdout.split()


def time_clatch(image, keypoints, threads, repeats, timer=EXAMPLE):
    fields = clatch(["time", image, keypoints, threads, repeats], timer)
    values = dict(zip(fields[::2], fields[1::2]))
    return int(values["descriptors"]), float(values["median_us"])


def time_opencv(cv2, gray, keypoints, repeats):
    latch = cv2.xfeatures2d.LATCH_create(64, True, 3)
    per_descriptor = []
    count = 0
    for _ in range(repeats):
        start = time.perf_counter()
        _, descriptors = latch.compute(gray, keypoints)
        seconds = time.perf_counter() - start
        count = len(descriptors)
        per_descriptor.append(seconds * 1e6 / count)
    return count, statistics.median(per_descriptor)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--keypoints", type=int, default=5000)
    parser.add_argument("--threshold", type=int, default=6)
    parser.add_argument("--threads", type=int, default=os.cpu_count())
    parser.add_argument("--baseline", help="another build of examples/cpu_describe, timed on 1 thread")
    args = parser.parse_args()
    try:
        import cv2
    except ImportError:
        sys.exit(f"skipped: OpenCV is not installed (python3 -m pip install {OPENCV_PIN})")
    if not os.access(EXAMPLE, os.X_OK):
        sys.exit("build the timer first: cargo build --release --example cpu_describe")
    cv2.setNumThreads(1)

    with tempfile.TemporaryDirectory() as tmp:
        source = cv2.imread(os.path.join(ROOT, "assets", "astronaut.png"), cv2.IMREAD_GRAYSCALE)
        gray = cv2.resize(source, (1024, 768), interpolation=cv2.INTER_LINEAR)
        image = os.path.join(tmp, "astronaut-1024x768.png")
        cv2.imwrite(image, gray)
        keypoint_file = os.path.join(tmp, "keypoints.txt")
        clatch(["detect", image, keypoint_file, args.keypoints, args.threshold])
        with open(keypoint_file) as f:
            rows = [list(map(float, line.split())) for line in f if line.strip()]
        keypoints = [cv2.KeyPoint(x, y, size, angle) for x, y, size, angle in rows]

        rounds = {"opencv": [], "clatch 1 thread": [], f"clatch {args.threads} threads": []}
        if args.baseline:
            rounds["baseline 1 thread"] = []
        counts = set()
        for _ in range(args.rounds):
            n, us = time_opencv(cv2, gray, keypoints, args.repeats)
            rounds["opencv"].append(us)
            counts.add(("opencv", n))
            for threads, name in [(1, "clatch 1 thread"), (args.threads, f"clatch {args.threads} threads")]:
                n, us = time_clatch(image, keypoint_file, threads, args.repeats)
                rounds[name].append(us)
                counts.add(("clatch", n))
            if args.baseline:
                n, us = time_clatch(image, keypoint_file, 1, args.repeats, args.baseline)
                rounds["baseline 1 thread"].append(us)
                counts.add(("baseline", n))

    print(f"CPU: {cpu_model()}, {os.cpu_count()} logical CPUs; OpenCV {cv2.__version__}")
    print(f"image: astronaut 1024x768, {len(keypoints)} keypoints; described: {sorted(counts)}")
    print(f"{args.rounds} rounds x {args.repeats} repeats; us per descriptor (median of round medians, "
          "min..max of round medians)")
    medians = {}
    for name, values in rounds.items():
        medians[name] = statistics.median(values)
        print(f"  {name:<18} {medians[name]:8.2f}   ({min(values):.2f}..{max(values):.2f})")
    opencv = medians["opencv"]
    for name, value in medians.items():
        if name != "opencv":
            print(f"  OpenCV / {name}: {opencv / value:.2f}x")
    if args.baseline:
        speedup = medians["baseline 1 thread"] / medians["clatch 1 thread"]
        print(f"  baseline / clatch, 1 thread: {speedup:.2f}x")


if __name__ == "__main__":
    main()
