"""Time link, twist and writhe per frame against PyElastica's knot_theory; print Markdown.

    python benchmarks/bench_topology.py [--repeats 30] [--sizes 50 100 150 200 400]

Timings are medians after a warm-up call (compilation excluded), with the minimum in
brackets: on a shared machine the median shows the typical cost, the minimum the cost
without interference. Values are printed too, so that agreement with PyElastica is visible;
its closure uses extensions of finite length, ours defaults to the infinite limit, so both
are listed.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import warnings
from importlib import metadata

import numba
import numpy as np

from rodphase import topology as T


def cpu_model():
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def test_rod(n):
    """n segments: a 3-turn helix (radius 0.1 m, pitch angle 0.6 rad) between axial leads.

    d1 is the Frenet normal turned by two extra turns along the rod, so that twist, writhe
    and link are all non-trivial. Lk is 2 + 3 = 5 (coaxial leads, Frenet Lk = 3 turns).
    """
    radius, psi, turns = 0.1, 0.6, 3
    c = radius / np.tan(psi)
    helix_len = turns * 2 * np.pi * np.hypot(radius, c)
    lead = 0.2
    s = np.linspace(0.0, helix_len + 2 * lead, n + 1)
    th = np.clip((s - lead) / np.hypot(radius, c), 0.0, 2 * np.pi * turns)
    z = c * th + np.minimum(s - lead, 0.0) + np.maximum(s - lead - helix_len, 0.0)
    pts = np.stack([radius * np.cos(th), radius * np.sin(th), z], axis=1)
    mid = 0.5 * (pts[1:] + pts[:-1])
    ang = np.arctan2(mid[:, 1], mid[:, 0])
    frenet = -np.stack([np.cos(ang), np.sin(ang), np.zeros(n)], axis=1)
    tang = np.diff(pts, axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    extra = 2 * 2 * np.pi * np.arange(n) / (n - 1)
    d1 = np.cos(extra)[:, None] * frenet + np.sin(extra)[:, None] * np.cross(tang, frenet)
    return pts, d1, s[-1]


def timed(repeats, fn, *args):
    fn(*args)  # warm-up: compilation and caches
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        value = fn(*args)
        samples.append(time.perf_counter() - t0)
    samples = np.array(samples) * 1e3
    return float(np.median(samples)), float(samples.min()), value


def fmt(med_min):
    med, mn = med_min
    return f"{med:.3f} ({mn:.3f})"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--sizes", type=int, nargs="+", default=[50, 100, 150, 200, 400])
    args = parser.parse_args()

    # PyElastica's kernels warn about non-contiguous np.dot; not our concern here.
    warnings.filterwarnings("ignore", category=numba.NumbaPerformanceWarning)
    try:
        from elastica.rod.knot_theory import compute_link, compute_twist, compute_writhe
    except Exception as exc:  # noqa: BLE001 - optional comparison only
        print(f"(PyElastica not importable: {exc}; its columns are left out)\n")
        compute_link = compute_twist = compute_writhe = None

    threads = numba.get_num_threads()
    warm_pts, warm_d1, _ = test_rod(50)
    default_min = T.PARALLEL_MIN_PAIRS
    T.PARALLEL_MIN_PAIRS = 0
    try:
        T.link(warm_pts, warm_d1)  # starts numba's thread pool, so its layer can be reported
    finally:
        T.PARALLEL_MIN_PAIRS = default_min
    try:
        layer = numba.threading_layer()
    except ValueError:
        layer = "not started"
    print("## Topology cost per frame\n")
    print(
        f"- CPU: {cpu_model()}; nproc {os.cpu_count()}; "
        f"load average {os.getloadavg()[0]:.2f} at start"
    )
    print(
        f"- numba {numba.__version__}, {threads} threads "
        f"(layer: {layer}); calls thread from {T.PARALLEL_MIN_PAIRS:,} segment pairs "
        f"(`PARALLEL_MIN_PAIRS`), so the first columns are single-threaded at these sizes; "
        f"numpy {np.__version__}"
    )
    if compute_writhe is not None:
        print(
            f"- PyElastica {metadata.version('pyelastica')} (`elastica.rod.knot_theory`, "
            "serial, asin form of Klenin & Langowski)"
        )
    print(f"- ms per frame, median of {args.repeats} after warm-up (minimum in brackets)\n")

    head = f"| n | writhe | link | twist | writhe {threads} threads | link {threads} threads |"
    rule = "|---|---|---|---|---|---|"
    if compute_writhe is not None:
        head += " PyElastica writhe | PyElastica link | PyElastica twist |"
        rule += "---|---|---|"
    print(head)
    print(rule)
    values = []
    for n in args.sizes:
        pts, d1, length = test_rod(n)
        row = {}
        row["wr"] = timed(args.repeats, T.writhe, pts)
        row["lk"] = timed(args.repeats, T.link, pts, d1)
        row["tw"] = timed(args.repeats, T.twist, pts, d1)
        T.PARALLEL_MIN_PAIRS = 0  # force the threaded kernels
        try:
            row["wrp"] = timed(args.repeats, T.writhe, pts)
            row["lkp"] = timed(args.repeats, T.link, pts, d1)
        finally:
            T.PARALLEL_MIN_PAIRS = default_min
        ext = 100.0 * length
        offset = T.EDGE_OFFSET_FRACTION * np.linalg.norm(np.diff(pts, axis=0), axis=1).min()
        vals = {
            "n": n,
            "Lk": row["lk"][2],
            "Tw": row["tw"][2],
            "Wr": row["wr"][2],
            "Lk 100L": T.link(pts, d1, extension=ext),
            "Wr 100L": T.writhe(pts, extension=ext),
        }
        line = (
            f"| {n} | {fmt(row['wr'][:2])} | {fmt(row['lk'][:2])} | {fmt(row['tw'][:2])} "
            f"| {fmt(row['wrp'][:2])} | {fmt(row['lkp'][:2])} |"
        )
        if compute_writhe is not None:
            cl = np.ascontiguousarray(pts.T[None])
            nc = np.ascontiguousarray(d1.T[None])
            rad = np.full((1, n), offset)
            slow = max(3, args.repeats // 5)  # PyElastica is ~100x slower
            pw = timed(slow, compute_writhe, cl, ext, "next_tangent")
            pl = timed(slow, compute_link, cl, nc, rad, ext, "next_tangent")
            pt = timed(slow, compute_twist, cl, nc)
            vals.update({"PyE Lk": pl[2][0], "PyE Tw": pt[2][0][0], "PyE Wr": pw[2][0]})
            line += f" {fmt(pw[:2])} | {fmt(pl[:2])} | {fmt(pt[:2])} |"
        print(line)
        values.append(vals)

    print("\n## Values (turns) for the same frames\n")
    print(
        "Ours with the default closure (infinite extensions), and differences: ours with "
        "extensions of 100 L (PyElastica's closure in this call) minus ours, and ours minus "
        "PyElastica at equal closure. Ribbon edge offset 0.1 x shortest segment in both. "
        "Expected Lk = 5 (2 extra turns + 3 helical turns of a Frenet ribbon, coaxial "
        "leads).\n"
    )
    head = "| n | Lk | Tw | Wr | Lk - Tw - Wr | Wr(100 L) - Wr |"
    rule = "|---|---|---|---|---|---|"
    if compute_writhe is not None:
        head += " dLk vs PyE | dTw vs PyE | dWr vs PyE |"
        rule += "---|---|---|"
    print(head)
    print(rule)
    for v in values:
        line = (
            f"| {v['n']} | {v['Lk']:.9f} | {v['Tw']:.9f} | {v['Wr']:.9f} "
            f"| {v['Lk'] - v['Tw'] - v['Wr']:.1e} | {v['Wr 100L'] - v['Wr']:.1e} |"
        )
        if compute_writhe is not None:
            line += (
                f" {v['Lk 100L'] - v['PyE Lk']:.1e} | {v['Tw'] - v['PyE Tw']:.1e} "
                f"| {v['Wr 100L'] - v['PyE Wr']:.1e} |"
            )
        print(line)

    # Whole histories: one frame per thread.
    pts, d1, _ = test_rod(150)
    S = 64
    hp = np.repeat(pts[None], S, axis=0)
    hd = np.repeat(d1[None], S, axis=0)
    med, mn, _ = timed(max(3, args.repeats // 5), T.topology_history, hp, hd)
    print(
        f"\n`topology_history`, {S} frames of n = 150: {med / S:.3f} ms per frame "
        f"(min {mn / S:.3f}) for Lk, Tw and Wr together."
    )


if __name__ == "__main__":
    main()
