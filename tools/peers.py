#!/usr/bin/env python3
"""The peers clatch is measured against, on the same machine and in the same run as its GPU benches.

Matching (needs PyTorch with CUDA): brute-force Hamming k = 2 of random 512-bit descriptors the way a GPU
user would write it today: descriptors unpacked once to +-1 vectors, then per chunk of queries one GEMM
(`torch.mm` in fp16, `torch._int_mm` in int8) and `torch.topk(k=2)`; CUDA events around the GEMMs and
top-k of all chunks (the unpacking is outside the timing, the baseline's best case), median of the runs
after warm-up. Pairs per second.

Collections (`--collection`, needs PyTorch with CUDA): exhaustive matching of S sets of n random 512-bit
descriptors (every pair a < b, ratio 0.8 and cross-check), as benches/gpu_collection.rs does with clatch,
written the way a PyTorch user would: all sets unpacked once to +-1 fp16 on the device, then per batch
of pairs one `torch.bmm` of the gathered query and gallery sets, `torch.topk(k=2)` along the gallery for
the ratio test and a max along the queries for the cross-check, the kept matches counted on the device.
CUDA events around all batches (the unpacking outside, the baseline's best case), after a warm-up on the
first batches; one timed run by default (`--collection-repeats`). `--collection-pairs P` times only the
first P pairs and extrapolates to all of them (said so in the output).

Extraction (needs opencv-contrib-python): OpenCV's LATCH (`cv2.xfeatures2d.LATCH_create(64, True, 3)`)
on the image and keypoints the clatch GPU bench dumped (`CLATCH_BENCH_DUMP=DIR cargo bench --features
cuda --bench gpu`): one process (OpenCV's LATCH is single-threaded), and the keypoints split over one
process per CPU core (all cores). Microseconds per descriptor.

Prints a table and writes JSON (`--out`). Missing packages are reported as skipped, never faked.

    python3 tools/peers.py --dump DIR --out peers.json
"""

import argparse
import json
import os
import statistics
import sys
import time

# Reference figures from elsewhere, never measured here (CLATCH: Parker et al., "CLATCH: A CUDA-based
# implementation of LATCH", 2016).
PAPER = {
    "clatch_paper_us_per_descriptor_gtx970m": 0.5,
    "clatch_paper_matcher_comparisons_per_s_gtx970m": 3e9,
}


def median_ms(torch, fn, warmup, repeats):
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        start = torch.cuda.Event(enable_timing=True)
        end = torch.cuda.Event(enable_timing=True)
        start.record()
        fn()
        end.record()
        torch.cuda.synchronize()
        times.append(start.elapsed_time(end))
    return statistics.median(times)


def torch_cuda(seed):
    """PyTorch, its CUDA device, a generator seeded with `seed` and the results header; or (None, the
    reason it is skipped)."""
    try:
        import torch
    except ImportError:
        return None, None, None, {"skipped": "PyTorch not installed"}
    if not torch.cuda.is_available():
        return None, None, None, {"skipped": "no CUDA device for PyTorch"}
    dev = torch.device("cuda")
    gen = torch.Generator(device=dev)
    gen.manual_seed(seed)
    return torch, dev, gen, {"device": torch.cuda.get_device_name(0), "torch": torch.__version__, "runs": []}


def torch_matching(sizes, repeats):
    torch, dev, gen, results = torch_cuda(2024)
    if torch is None:
        return results
    budget = 1 << 30  # bytes of one chunk's score matrix
    for n in sizes:
        bits_q = torch.randint(0, 2, (n, 512), generator=gen, device=dev, dtype=torch.int8)
        bits_g = torch.randint(0, 2, (n, 512), generator=gen, device=dev, dtype=torch.int8)
        for kind in ["fp16", "int8"]:
            if kind == "fp16":
                q = (1 - 2 * bits_q).to(torch.float16)
                g = (1 - 2 * bits_g).to(torch.float16)
                gt = g.t().contiguous()
                elem = 2
                gemm = lambda a, b=gt: torch.mm(a, b)  # noqa: E731
            else:
                if not hasattr(torch, "_int_mm"):
                    results["runs"].append({"n": n, "kind": kind, "skipped": "no torch._int_mm"})
                    continue
                q = (1 - 2 * bits_q).contiguous()
                g = (1 - 2 * bits_g)
                gt = g.t().contiguous()
                elem = 4
                gemm = lambda a, b=gt: torch._int_mm(a, b)  # noqa: E731
            chunk = max(32, min(n, budget // (elem * n)))
            chunk -= chunk % 32 if chunk > 32 else 0

            def run():
                out = []
                for s in range(0, n, chunk):
                    scores = gemm(q[s : s + chunk])
                    out.append(torch.topk(scores, 2, dim=1))
                return out

            def gemm_only():
                for s in range(0, n, chunk):
                    gemm(q[s : s + chunk])

            # Correctness of the baseline itself: distances from the top-2 dot products equal a direct
            # Hamming count for a few queries.
            try:
                top = run()[0]
            except RuntimeError as e:
                results["runs"].append({"n": n, "kind": kind, "skipped": f"{type(e).__name__}: {e}"[:200]})
                continue
            d_baseline = ((512 - top.values[:4].float()) / 2).round().long()
            direct = (bits_q[:4, None, :] != bits_g[None, :, :]).sum(-1)
            d_direct = torch.topk(direct, 2, dim=1, largest=False).values
            if not torch.equal(d_baseline.sort(dim=1).values, d_direct.sort(dim=1).values):
                raise SystemExit(f"baseline {kind} n={n}: distances disagree with a direct count")
            reps = repeats if n <= 65536 else max(3, repeats // 3)
            ms = median_ms(torch, run, 2, reps)
            ms_gemm = median_ms(torch, gemm_only, 2, reps)
            results["runs"].append(
                {
                    "n": n,
                    "kind": kind,
                    "chunk": chunk,
                    "ms": ms,
                    "pairs_per_s": n * n / (ms * 1e-3),
                    "gemm_ms": ms_gemm,
                    "gemm_pairs_per_s": n * n / (ms_gemm * 1e-3),
                    "runs": reps,
                }
            )
            del q, g, gt
            torch.cuda.empty_cache()
    return results


def torch_collection(set_count, sizes, repeats, limit_pairs):
    torch, dev, gen, results = torch_cuda(2025)
    if torch is None:
        return results
    budget = 1 << 30  # bytes of one batch's score tensor
    for n in sizes:
        bits = torch.randint(0, 2, (set_count, n, 512), generator=gen, device=dev, dtype=torch.int8)
        signs = (1 - 2 * bits).to(torch.float16)
        first_bits = bits[:2].clone()
        del bits
        a_all, b_all = torch.triu_indices(set_count, set_count, offset=1, device=dev)
        total = a_all.numel()
        pairs = total if limit_pairs is None else min(total, limit_pairs)
        batch = max(1, budget // (2 * n * n))
        arange = torch.arange(n, device=dev)

        def run(count):
            kept = torch.zeros((), dtype=torch.int64, device=dev)
            for s in range(0, count, batch):
                a = a_all[s : min(s + batch, count)]
                b = b_all[s : min(s + batch, count)]
                scores = torch.bmm(signs[a], signs[b].transpose(1, 2))  # (B, n, n): 512 - 2 distance
                top = torch.topk(scores, 2, dim=2)
                d1 = (512 - top.values[..., 0].float()) / 2
                d2 = (512 - top.values[..., 1].float()) / 2
                nearest_query = scores.max(dim=1).indices  # (B, n): per gallery row
                mutual = nearest_query.gather(1, top.indices[..., 0]) == arange
                kept += ((d1 < 0.8 * d2) & mutual).sum()
            return kept

        # The baseline's own check: its top-2 distances of pair (0, 1) equal a direct count.
        scores = torch.mm(signs[0, :4], signs[1].t())
        d_baseline = ((512 - torch.topk(scores, 2, dim=1).values.float()) / 2).round().long()
        direct = (first_bits[0, :4, None, :] != first_bits[1][None, :, :]).sum(-1)
        d_direct = torch.topk(direct, 2, dim=1, largest=False).values
        if not torch.equal(d_baseline.sort(dim=1).values, d_direct.sort(dim=1).values):
            raise SystemExit(f"collection baseline n={n}: distances disagree with a direct count")
        run(min(pairs, 4 * batch))  # warm-up
        kept = []
        ms = median_ms(torch, lambda: kept.append(run(pairs)), 0, repeats)
        seconds = ms / 1e3 * total / pairs
        results["runs"].append(
            {
                "sets": set_count,
                "n": n,
                "pairs": total,
                "timed_pairs": pairs,
                "extrapolated": pairs < total,
                "batch": batch,
                "seconds": seconds,
                "pairs_per_s": total / seconds,
                "descriptor_pairs_per_s": total * n * n / seconds,
                "kept_in_timed_pairs": int(kept[-1]),
                "runs": repeats,
            }
        )
        del signs
        torch.cuda.empty_cache()
    return results


def read_keypoints(path):
    with open(path) as f:
        next(f)
        return [tuple(float(v) for v in line.split(",")) for line in f if line.strip()]


_worker = {}


def _init_worker(image_path):
    import cv2

    cv2.setNumThreads(1)
    _worker["image"] = cv2.imread(image_path, cv2.IMREAD_GRAYSCALE)
    _worker["latch"] = cv2.xfeatures2d.LATCH_create(64, True, 3)


def _describe(rows):
    import cv2

    kps = [cv2.KeyPoint(x, y, size, angle) for (x, y, size, angle) in rows]
    _, desc = _worker["latch"].compute(_worker["image"], kps)
    return 0 if desc is None else len(desc)


def opencv_latch(dump, repeats):
    try:
        import cv2
    except ImportError:
        return {"skipped": "opencv-contrib-python not installed"}
    if not hasattr(cv2, "xfeatures2d"):
        return {"skipped": "cv2 without xfeatures2d (install opencv-contrib-python)"}
    import multiprocessing as mp

    results = {"cv2": cv2.__version__, "cores": os.cpu_count(), "runs": []}
    for name in ["1080p", "5616x3744"]:
        image_path = os.path.join(dump, f"{name}.pgm")
        kp_path = os.path.join(dump, f"{name}_10000.csv")
        if not (os.path.exists(image_path) and os.path.exists(kp_path)):
            results["runs"].append({"image": name, "skipped": f"no dump in {dump}"})
            continue
        rows = read_keypoints(kp_path)
        _init_worker(image_path)
        single = []
        for _ in range(repeats):
            t = time.perf_counter()
            described = _describe(rows)
            single.append(time.perf_counter() - t)
        cores = os.cpu_count() or 1
        parts = [rows[i::cores] for i in range(cores)]
        with mp.get_context("fork").Pool(cores, _init_worker, (image_path,)) as pool:
            pool.map(_describe, parts)  # warm-up: workers loaded
            multi = []
            for _ in range(repeats):
                t = time.perf_counter()
                described_all = sum(pool.map(_describe, parts))
                multi.append(time.perf_counter() - t)
        results["runs"].append(
            {
                "image": name,
                "keypoints": len(rows),
                "described": described,
                "described_all_cores": described_all,
                "us_per_descriptor_1_thread": statistics.median(single) * 1e6 / described,
                "us_per_descriptor_all_cores": statistics.median(multi) * 1e6 / described_all,
                "runs": repeats,
            }
        )
    return results


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dump", default=None, help="directory written by the GPU bench (CLATCH_BENCH_DUMP)")
    ap.add_argument("--sizes", default="1024,16384,65536,131072")
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--out", default=None, help="write the results as JSON here")
    ap.add_argument("--collection", action="store_true", help="the exhaustive collection baseline too")
    ap.add_argument("--collection-sets", type=int, default=1000)
    ap.add_argument("--collection-sizes", default="5000,2000")
    ap.add_argument("--collection-repeats", type=int, default=1)
    ap.add_argument("--collection-pairs", type=int, default=None, help="time only this many pairs")
    ap.add_argument("--skip-matching", action="store_true", help="leave out the N x N kNN baseline")
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    report = {
        "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
        "paper": PAPER,
        "matching": {"skipped": "--skip-matching"} if args.skip_matching else torch_matching(sizes, args.repeats),
        "collection": torch_collection(
            args.collection_sets,
            [int(s) for s in args.collection_sizes.split(",")],
            args.collection_repeats,
            args.collection_pairs,
        )
        if args.collection
        else {"skipped": "no --collection"},
        "extraction": opencv_latch(args.dump, 5) if args.dump else {"skipped": "no --dump"},
    }
    m = report["matching"]
    if "skipped" in m:
        print(f"matching peers: skipped: {m['skipped']}")
    else:
        print(f"PyTorch {m['torch']} on {m['device']}, k = 2, 512 bits, +-1 GEMM + topk, CUDA events:")
        for r in m["runs"]:
            if "skipped" in r:
                print(f"  {r['kind']} {r['n']}: skipped: {r['skipped']}")
                continue
            print(
                f"  {r['kind']:<5} {r['n']:>6} x {r['n']:<6}: median {r['ms']:9.3} ms "
                f"{r['pairs_per_s'] / 1e9:8.1f} G pairs/s (GEMM alone {r['gemm_pairs_per_s'] / 1e9:8.1f}; "
                f"chunks of {r['chunk']}, {r['runs']} runs)"
            )
    c = report["collection"]
    if "skipped" in c:
        print(f"collection peers: skipped: {c['skipped']}")
    else:
        print(f"PyTorch {c['torch']} on {c['device']}, exhaustive collection, ratio 0.8 + cross-check, +-1 fp16 bmm:")
        for r in c["runs"]:
            how = f"extrapolated from {r['timed_pairs']} pairs" if r["extrapolated"] else "all pairs timed"
            print(
                f"  {r['sets']} sets x {r['n']}, {r['pairs']} pairs: {r['seconds']:9.3f} s "
                f"{r['pairs_per_s']:9.0f} pairs/s {r['descriptor_pairs_per_s'] / 1e9:7.1f} G descriptor pairs/s "
                f"({how}; batches of {r['batch']} pairs, {r['runs']} runs)"
            )
    e = report["extraction"]
    if "skipped" in e:
        print(f"extraction peers: skipped: {e['skipped']}")
    else:
        print(f"OpenCV {e['cv2']} LATCH_create(64, True, 3), {e['cores']} cores:")
        for r in e["runs"]:
            if "skipped" in r:
                print(f"  {r['image']}: skipped: {r['skipped']}")
                continue
            print(
                f"  {r['image']:>9}, {r['keypoints']} keypoints ({r['described']} described): "
                f"{r['us_per_descriptor_1_thread']:.2f} us/descriptor on 1 thread, "
                f"{r['us_per_descriptor_all_cores']:.2f} us/descriptor on all cores"
            )
    print(
        "paper (for reference, not measured here): CLATCH 0.5 us/descriptor on a GTX 970M; "
        "matcher 3e9 comparisons/s"
    )
    if args.out:
        with open(args.out, "w") as f:
            json.dump(report, f, indent=1)


if __name__ == "__main__":
    sys.exit(main())
