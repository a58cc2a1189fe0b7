#!/usr/bin/python3
"""The same TL fit + apply as test/bench/bench_tl.cpp, written plainly in numpy/scipy.

Prints: numpy N fit_s apply_s total_s peak_rss_MB value_at_middle
"""
import resource
import sys
import time

import numpy as np
from scipy import signal


def tl_matrix(b, scale=50000.0):
    bt = np.linalg.norm(b, axis=1)
    bh = b / bt[:, None]
    db = np.gradient(b, axis=0)  # central difference per sample, one-sided ends
    cols = [bh[:, 0], bh[:, 1], bh[:, 2]]
    for i, j in [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]:
        cols.append(bh[:, i] * b[:, j] / scale)
    for i in range(3):
        for j in range(3):
            cols.append(bh[:, i] * db[:, j] / scale)
    return np.column_stack(cols)


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 36000
    t = 0.1 * np.arange(n)
    b = np.column_stack([
        17000 + 3000 * np.sin(0.05 * t) + 200 * np.sin(1.3 * t),
        -4000 + 2500 * np.cos(0.031 * t) + 150 * np.sin(0.9 * t),
        50000 + 800 * np.sin(0.021 * t)])
    s = np.linalg.norm(b, axis=1) + 3 * np.sin(0.7 * t)
    t0 = time.perf_counter()
    a = tl_matrix(b)
    sos = signal.butter(4, [0.1, 0.9], btype="band", fs=10.0, output="sos")
    af = signal.sosfiltfilt(sos, a, axis=0)[20:-20]
    sf = signal.sosfiltfilt(sos, s)[20:-20]
    coef = np.linalg.solve(af.T @ af + 0.025 * np.eye(a.shape[1]), af.T @ sf)
    t1 = time.perf_counter()
    comp = s - tl_matrix(b) @ coef
    t2 = time.perf_counter()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"numpy {n} {t1 - t0:.4f} {t2 - t1:.4f} {t2 - t0:.4f} {rss:.1f} {comp[n // 2]:.6f}")


if __name__ == "__main__":
    main()
