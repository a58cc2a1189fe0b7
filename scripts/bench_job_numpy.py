#!/usr/bin/python3
"""The whole TL job of `magcomp calibrate` + `magcomp evaluate` in numpy/scipy, on a flight file.

Reads only the fields it needs (h5py), fits TL (18 columns, band-pass 0.1-0.9 Hz order 4 on each
calibration segment, zero-phase, trim 20, ridge lambda) on the calibration lines, applies it to the
whole flight and prints the error std against mag_1_c (each line's mean removed).
Usage: bench_job_numpy.py FLIGHT.h5 LINES LAMBDA   (LINES comma-separated)
Prints: numpy <samples> <seconds> <peak_rss_MB> <std_nT>
With --read-only: reads the needed columns and prints: floor <samples> <seconds>
"""
import resource
import sys
import time

t_start = time.perf_counter()
import h5py  # noqa: E402
import numpy as np  # noqa: E402
from scipy import signal  # noqa: E402

FIELDS = ["tt", "line", "mag_5_uc", "flux_c_x", "flux_c_y", "flux_c_z", "mag_1_c"]


def tl_matrix(b, scale=50000.0):
    bt = np.linalg.norm(b, axis=1)
    bh = b / bt[:, None]
    db = np.gradient(b, axis=0)
    cols = [bh[:, 0], bh[:, 1], bh[:, 2]]
    for i, j in [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]:
        cols.append(bh[:, i] * b[:, j] / scale)
    for i in range(3):
        for j in range(3):
            cols.append(bh[:, i] * db[:, j] / scale)
    return np.column_stack(cols)


def main():
    path = sys.argv[1]
    if "--read-only" in sys.argv:
        t0 = time.perf_counter()
        with h5py.File(path, "r") as f:
            cols = [f[k][()] for k in FIELDS]
        print(f"floor {len(cols[0])} {time.perf_counter() - t0:.4f}")
        return
    lines = [float(x) for x in sys.argv[2].split(",")]
    lam = float(sys.argv[3])
    with h5py.File(path, "r") as f:
        d = {k: f[k][()] for k in FIELDS}
    b = np.column_stack([d["flux_c_x"], d["flux_c_y"], d["flux_c_z"]])
    s, line, ref = d["mag_5_uc"], d["line"], d["mag_1_c"]
    a = tl_matrix(b)
    sos = signal.butter(4, [0.1, 0.9], btype="band", fs=10.0, output="sos")
    sel = np.isin(np.round(line, 6), np.round(lines, 6))
    edges = np.flatnonzero(np.diff(np.concatenate([[0], sel.astype(int), [0]])))
    af, sf = [], []
    for start, stop in zip(edges[::2], edges[1::2]):
        if stop - start < 50:
            continue
        af.append(signal.sosfiltfilt(sos, a[start:stop], axis=0)[20:-20])
        sf.append(signal.sosfiltfilt(sos, s[start:stop])[20:-20])
    af, sf = np.vstack(af), np.concatenate(sf)
    coef = np.linalg.solve(af.T @ af + lam * np.eye(a.shape[1]), af.T @ sf)
    err = s - a @ coef - ref
    ss = n = 0
    for l in np.unique(line):
        e = err[line == l]
        ss += ((e - e.mean()) ** 2).sum()
        n += len(e)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"numpy {len(s)} {time.perf_counter() - t_start:.4f} {rss:.1f} {np.sqrt(ss / n):.4f}")


if __name__ == "__main__":
    main()
