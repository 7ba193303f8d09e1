#!/usr/bin/env python3
"""Fits the recognizer's verification score (vision::EvidenceScore) as boosted decision trees.

Input: the rows that `TEACHSIM_RECOGNIZE_FEATURES=FILE teachsim bench recognize` appends, one per
fitted hypothesis (see fit_evidence_weights.py, whose reader this uses); a hypothesis is true when
its projected vertices lie within 3 px of a true block of its model (mean distance).
Output: src/vision/evidence_trees.inc (--out), the trees and their calibration as C++ constants
(vision::BoostedEvidenceScore), and how the score separates true from false hypotheses on every
file given (the first is the training set, the rest held out) against the logistic score
(vision::EvidenceScore) at the same thresholds.

The trees: gradient boosting of the logistic loss (Friedman 2001) with second-order leaves (as
XGBoost), depth 3, splits on histogram bins of the training values. The calibration maps the trees'
sum onto the logistic score's scale by the false hypotheses' ranks: above any threshold, as many
false hypotheses pass the new score as pass the logistic one, so the recognizer's thresholds (chosen
on that scale) keep what they let through of false poses, and more true ones pass. Calibrate on
rows the trees were not fitted on (--calibrate): on their own training rows boosted trees are
surer than on new ones, and the top of the scale (0.98-0.996, the occlusion pass's) lets more false
poses through. Pure Python (no numpy), about half a minute on 60,000 rows.

The recognizer's trees (session 69):
  TEACHSIM_RECOGNIZE_FEATURES=train.tsv teachsim bench recognize --no-peer --render-seeds 7-22
  TEACHSIM_RECOGNIZE_FEATURES=calibrate.tsv teachsim bench recognize --no-peer --render-seeds 23-38
  tools/fit_evidence_trees.py --calibrate calibrate.tsv --out src/vision/evidence_trees.inc train.tsv

Usage: tools/fit_evidence_trees.py [--trees N] [--calibrate FILE] [--out FILE] TRAIN.tsv [HELD_OUT.tsv ...]
"""
import argparse
import bisect
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fit_evidence_weights import load  # noqa: E402

# The features, in EvidenceScore's order (recognizer.cc, EvidenceFeatures).
FEATURES = ["matched", "support", "coverage", "rms", "rms_closest", "cont", "long_cont", "fixed_share",
            "free_support", "free_coverage", "polarity", "edges_supported_fraction", "edges_visible",
            "edges_supported", "step_share", "supported_px", "matches"]
# The logistic score of sessions 6-69 (fit_evidence_weights.py on seeds 7 and 8): the scale on which
# the recognizer's thresholds were chosen, and the reference of the calibration.
LOGISTIC = [6.8563, -4.0041, 2.9860, -0.9108, -1.2449, -0.8988, 0.5762, -3.7774, -3.7323, 5.8348, 1.1887,
            -0.4480, -0.4147, 1.2771]
LOGISTIC_INTERCEPT = -2.2347
DEPTH, RATE, LAMBDA, MIN_HESSIAN, BINS = 3, 0.1, 1.0, 5.0, 32


def features(row):
    visible = max(row["edges_visible"], 1)
    return [row["matched"], row["support"], row["coverage"], min(row["rms"], 4.0), min(row["rms_closest"], 4.0),
            row["cont"], row["long_cont"], row["fixed_share"], row["free_support"], row["free_coverage"],
            row["polarity"], row["edges_supported"] / visible, row["edges_visible"], row["edges_supported"],
            row["step_supported_px"] / max(row["supported_px"], 1.0), row["supported_px"], row["matches"]]


def logistic(x):
    z = LOGISTIC_INTERCEPT + sum(w * v for w, v in zip(LOGISTIC, x[:len(LOGISTIC)]))
    return 1 / (1 + math.exp(-z))


def bin_edges(xs):
    """Per feature, the split candidates: midpoints between distinct values, or BINS quantiles."""
    edges = []
    for j in range(len(xs[0])):
        values = sorted(set(x[j] for x in xs))
        if len(values) <= BINS:
            edges.append([(values[i] + values[i + 1]) / 2 for i in range(len(values) - 1)])
        else:
            column = sorted(x[j] for x in xs)
            cuts = sorted(set(column[len(column) * k // BINS] for k in range(1, BINS)))
            # A cut at a value sends that value left (x <= cut): keep only cuts below the maximum.
            edges.append([c for c in cuts if c < column[-1]])
    return edges


def grow(index, binned, grad, hess, edges, depth):
    """One tree on the rows `index`: ('leaf', value) or ('split', feature, bin, left, right)."""
    g_all = sum(grad[i] for i in index)
    h_all = sum(hess[i] for i in index)
    if depth == 0 or len(index) < 20:
        return ("leaf", -g_all / (h_all + LAMBDA))
    best_gain, best = 0.0, None
    for j, e in enumerate(edges):
        g_bin, h_bin = [0.0] * (len(e) + 1), [0.0] * (len(e) + 1)
        for i in index:
            g_bin[binned[i][j]] += grad[i]
            h_bin[binned[i][j]] += hess[i]
        g_left = h_left = 0.0
        for b in range(len(e)):
            g_left += g_bin[b]
            h_left += h_bin[b]
            g_right, h_right = g_all - g_left, h_all - h_left
            if h_left < MIN_HESSIAN or h_right < MIN_HESSIAN:
                continue
            gain = g_left ** 2 / (h_left + LAMBDA) + g_right ** 2 / (h_right + LAMBDA) - g_all ** 2 / (h_all + LAMBDA)
            if gain > best_gain:
                best_gain, best = gain, (j, b)
    if best is None:
        return ("leaf", -g_all / (h_all + LAMBDA))
    j, b = best
    left = [i for i in index if binned[i][j] <= b]
    right = [i for i in index if binned[i][j] > b]
    return ("split", j, b, grow(left, binned, grad, hess, edges, depth - 1),
            grow(right, binned, grad, hess, edges, depth - 1))


def predict(tree, bins):
    while tree[0] == "split":
        tree = tree[3] if bins[tree[1]] <= tree[2] else tree[4]
    return tree[1]


def boost(xs, ys, n_trees):
    edges = bin_edges(xs)
    binned = [[bisect.bisect_left(e, x[j]) for j, e in enumerate(edges)] for x in xs]
    positives = sum(ys)
    base = math.log(positives / (len(ys) - positives))
    margin = [base] * len(xs)
    trees = []
    for t in range(n_trees):
        grad, hess = [], []
        for m, y in zip(margin, ys):
            p = 1 / (1 + math.exp(-m))
            grad.append(p - y)
            hess.append(max(p * (1 - p), 1e-6))
        tree = grow(list(range(len(xs))), binned, grad, hess, edges, DEPTH)
        trees.append(tree)
        for i, bins in enumerate(binned):
            margin[i] += RATE * predict(tree, bins)
        if (t + 1) % 20 == 0:
            print(f"  {t + 1} trees", file=sys.stderr)
    return base, edges, trees


def tree_margin(base, edges, trees, x):
    bins = [bisect.bisect_left(e, x[j]) for j, e in enumerate(edges)]
    return base + RATE * sum(predict(t, bins) for t in trees)


def calibration(margins, references):
    """Monotone points (margin, score): the false hypotheses' margins and logistic scores matched by
    rank from the top (each 5th of the first 2,000, then each 250th), then the ends."""
    m = sorted(margins, reverse=True)
    s = sorted(references, reverse=True)
    ranks = list(range(0, min(2000, len(m)), 5)) + list(range(2000, len(m), 250))
    points = []
    for r in ranks:
        if not points or (m[r] < points[-1][0] - 1e-9 and s[r] <= points[-1][1]):
            points.append((m[r], s[r]))
    points.reverse()
    # Below the lowest: down to 0; above the highest false margin: up to 1 at twice its distance.
    low, high = points[0], points[-1]
    points.insert(0, (low[0] - 10.0, 0.0))
    points.append((high[0] + 10.0, 1.0))
    return points


def write_inc(path, base, edges, trees, points, sources):
    nodes = []

    def emit(tree):
        at = len(nodes)
        nodes.append(None)
        if tree[0] == "leaf":
            nodes[at] = (-1, 0.0, -1, -1, RATE * tree[1])
        else:
            left = emit(tree[3])
            right = emit(tree[4])
            nodes[at] = (tree[1], edges[tree[1]][tree[2]], left, right, 0.0)
        return at

    roots = [emit(t) for t in trees]
    with open(path, "w") as f:
        f.write("// Generated by tools/fit_evidence_trees.py (" + sources + "); do not edit.\n")
        f.write("// clang-format off\n")
        f.write("// BoostedEvidenceScore's trees (features in EvidenceFeatures' order) and calibration.\n")
        f.write(f"constexpr double kEvidenceTreeBase = {base!r};\n")
        f.write(f"constexpr int kEvidenceTreeFeatures = {len(FEATURES)};\n")
        f.write("constexpr EvidenceTreeNode kEvidenceTreeNodes[] = {\n")
        for n in nodes:
            f.write(f"    {{{n[0]}, {n[1]!r}, {n[2]}, {n[3]}, {n[4]!r}}},\n")
        f.write("};\n")
        f.write("constexpr int kEvidenceTreeRoots[] = {" + ", ".join(str(r) for r in roots) + "};\n")
        f.write("constexpr EvidenceCalibrationPoint kEvidenceCalibration[] = {\n")
        for m, s in points:
            f.write(f"    {{{m!r}, {s!r}}},\n")
        f.write("};\n")
        f.write("// clang-format on\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trees", type=int, default=60, help="boosting rounds")
    parser.add_argument("--out", help="the C++ include to write (src/vision/evidence_trees.inc)")
    parser.add_argument("--calibrate", help="rows whose false hypotheses calibrate the score (default: the training rows)")
    parser.add_argument("train")
    parser.add_argument("held_out", nargs="*")
    args = parser.parse_args()
    rows = load(args.train, "render")
    if not rows or all(r["best"] >= 3 for r in rows) or all(r["best"] < 3 for r in rows):
        sys.exit(f"{args.train}: no render rows with both true and false hypotheses to fit")
    xs = [features(r) for r in rows]
    ys = [1 if r["best"] < 3 else 0 for r in rows]
    print(f"fitting {args.trees} trees on {len(rows)} hypotheses ({sum(ys)} true) of {args.train}")
    base, edges, trees = boost(xs, ys, args.trees)
    false_x = [x for x, y in zip(xs, ys) if y == 0]
    if args.calibrate:
        false_x = [features(r) for r in load(args.calibrate, "render") if r["best"] >= 3]
    points = calibration([tree_margin(base, edges, trees, x) for x in false_x], [logistic(x) for x in false_x])

    def score(x):
        m = tree_margin(base, edges, trees, x)
        k = bisect.bisect_left([p[0] for p in points], m)
        if k == 0:
            return points[0][1]
        if k == len(points):
            return points[-1][1]
        (m0, s0), (m1, s1) = points[k - 1], points[k]
        return s0 + (s1 - s0) * (m - m0) / (m1 - m0)

    for path in [args.train] + args.held_out:
        for which in ("render", "dev"):
            test = load(path, which)
            if not test:
                continue
            true_x = [features(r) for r in test if r["best"] < 3]
            false_x = [features(r) for r in test if r["best"] >= 3]
            line = [f"{path} [{which}]: {len(true_x)} true, {len(false_x)} false"]
            for t in (0.3, 0.8, 0.93, 0.98, 0.996):
                line.append(f">= {t}: true {sum(logistic(x) >= t for x in true_x)} -> "
                            f"{sum(score(x) >= t for x in true_x)}, false {sum(logistic(x) >= t for x in false_x)} -> "
                            f"{sum(score(x) >= t for x in false_x)}")
            print(";\n  ".join(line))
    if args.out:
        sources = f"fitted on {os.path.basename(args.train)}, calibrated on " + (
            os.path.basename(args.calibrate) if args.calibrate else "the same")
        write_inc(args.out, base, edges, trees, points, sources)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
