#!/usr/bin/env python3
"""What an ideal estimator could reach on the synth accuracy cases: the Cramér-Rao bound.

For each defect of a case the model family is known (a Gaussian bump or pit, or a ridge: the
Gaussian of the distance to a segment) and so are its true parameters. With scan points
spread at random (Poisson, `--density` points/mm²) over a window that covers the defect, and
Gaussian noise (`--noise`), the Fisher information of the model with a plane under it gives the
smallest standard deviation any unbiased estimator can have, of the peak and of the model's
height at each core point. From these:

- peaks: the expected number of bump and pit peaks off by more than 10 %, and of cases whose
  peaks are all within 10 % (ridges are left out: their peak is pinned by many points);
- IoU: per core point the probability that a height drawn around the truth with that standard
  deviation lies beyond the tolerance; the expected IoU of the case.

Input: the dumps the accuracy test writes with POLISHBOT_DUMP=PREFIX
(`PREFIX-SEED-Adaptive.csv`, with the columns truth and given, and `PREFIX-SEED-truth.json`):

    POLISHBOT_DUMP=/tmp/d/s POLISHBOT_SEEDS=11,12 cargo test --release --test compare \
        -- adaptive_finds
    python3 benches/analysis/ideal_bound.py /tmp/d/s 11 12

Needs numpy. docs/ALGORITHMS.md (adaptive step 13, "What is left") has the numbers.
"""
import argparse
import csv
import json
import math

import numpy as np

FWHM_PER_SIGMA = 2.354820045030949


def model(p, u, v):
    """Plane + Gaussian of the distance to a segment (half-length p[7]; 0: a round defect)."""
    a0, a1, a2, amp, cx, cy, theta, half, s = p
    c, sn = math.cos(theta), math.sin(theta)
    du, dv = u - cx, v - cy
    along = du * c + dv * sn
    across = -du * sn + dv * c
    along = np.sign(along) * np.maximum(np.abs(along) - half, 0.0)
    return a0 + a1 * u + a2 * v + amp * np.exp(-(along**2 + across**2) / (2 * s * s))


def jacobian(p, u, v, free):
    cols = []
    for k in free:
        e = np.zeros(9)
        e[k] = 1e-6 * max(1.0, abs(p[k]))
        cols.append((model(p + e, u, v) - model(p - e, u, v)) / (2 * e[k]))
    return np.stack(cols, 1)


def variances(defect, queries, density, noise, rng, reps):
    """Mean over `reps` random point sets of the CRB variance of the model's height at the
    `queries` ((u, v) pairs in the defect's frame; the first one is its peak)."""
    ridge = defect["kind"] == "ridge"
    s = defect["width"] / FWHM_PER_SIGMA
    half = defect["length"] / 2 if ridge else 0.0
    p = np.array([0, 0, 0, defect["height"], 0, 0, 0.0, half, s])
    free = [0, 1, 2, 3, 4, 5, 8] + ([6, 7] if ridge else [])
    radius = max(2.34, half + 3 * s + 0.5)
    qu, qv = queries
    total = np.zeros(len(qu))
    for _ in range(reps):
        n = rng.poisson(density * 4 * radius * radius)
        u, v = rng.uniform(-radius, radius, n), rng.uniform(-radius, radius, n)
        j = jacobian(p, u, v, free)
        fisher = j.T @ j / noise**2
        g = jacobian(p, qu, qv, free)
        total += np.einsum("ij,ji->i", g, np.linalg.solve(fisher, g.T))
    return total / reps


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("prefix")
    ap.add_argument("seeds", nargs="+")
    ap.add_argument("--density", type=float, default=19.0, help="scan points/mm² (300k: 19)")
    ap.add_argument("--noise", type=float, default=0.015)
    ap.add_argument("--tolerance", type=float, default=0.05)
    ap.add_argument("--reps", type=int, default=20)
    a = ap.parse_args()
    rng = np.random.default_rng(1)
    tol = a.tolerance
    expected_off, cases_within, ious = 0.0, 0.0, []
    erfc = np.vectorize(math.erfc)
    for seed in a.seeds:
        rows = list(csv.DictReader(open(f"{a.prefix}-{seed}-Adaptive.csv")))
        rows = [r for r in rows if r["given"] == "1"]
        pts = np.array([[float(r[k]) for k in "xyz"] for r in rows])
        truth = np.array([float(r["truth"]) for r in rows])
        sd = np.full(len(rows), 0.002)  # away from defects the truth is 0: never detected
        nearest = np.full(len(rows), np.inf)
        within = 1.0
        for d in json.load(open(f"{a.prefix}-{seed}-truth.json"))["defects"]:
            ridge = d["kind"] == "ridge"
            s = d["width"] / FWHM_PER_SIGMA
            half = d["length"] / 2 if ridge else 0.0
            offset = pts - np.array(d["centre"])
            dist = np.linalg.norm(offset, axis=1)
            near = (dist < half + 4 * s + 0.3) & (np.abs(truth) > 0.02)
            if ridge:
                axis = np.array(d["direction"])
                along = offset[near] @ axis
                across = np.linalg.norm(offset[near] - np.outer(along, axis), axis=1)
                qu, qv = along, across
            else:
                qu, qv = dist[near], np.zeros(near.sum())
            var = variances(d, (np.r_[0.0, qu], np.r_[0.0, qv]), a.density, a.noise, rng, a.reps)
            if not ridge and abs(d["height"]) > tol:
                off = math.erfc(0.1 * abs(d["height"]) / math.sqrt(var[0]) / math.sqrt(2))
                expected_off += off
                within *= 1 - off
            idx = np.where(near)[0]
            closer = dist[idx] < nearest[idx]
            sd[idx[closer]] = np.sqrt(var[1:][closer])
            nearest[idx[closer]] = dist[idx][closer]
        cases_within += within
        real = np.abs(truth) > tol
        detected = 0.5 * (erfc((tol - truth) / sd / math.sqrt(2)) + erfc((tol + truth) / sd / math.sqrt(2)))
        iou = detected[real].sum() / (real.sum() + detected[~real].sum())
        ious.append(iou)
        print(f"seed {seed}: {real.sum()} true error points, ideal expected IoU {iou:.3f}")
    print(f"ideal: mean IoU {np.mean(ious):.3f}, {sum(i >= 0.95 for i in ious)} of {len(ious)} cases >= 0.95;"
          f" bump/pit peaks off by more than 10 %: {expected_off:.1f} expected;"
          f" cases with every such peak within 10 %: {cases_within:.1f} of {len(ious)} expected")


if __name__ == "__main__":
    main()
