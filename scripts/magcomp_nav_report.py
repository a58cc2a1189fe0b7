#!/usr/bin/python3
"""magcomp navigation report: turns `magcomp navigate --report DIR` output (tracks.h5,
navigation.json) into DIR/index.html with PNG plots: the true, INS and filter tracks on the anomaly
map with the filter's 2-sigma ellipses, the horizontal errors against the filter's own 2-sigma
bound, and the innovations with their predicted spread."""
import html
import json
import os
import sys

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Ellipse  # noqa: E402

R_EARTH_M = 6378137.0


def ellipse_axes(cnn, cee, cne, k=2.0):
    """Semi-axes (m) and the angle (deg, from east, counter-clockwise) of the k-sigma ellipse of a
    horizontal covariance [[east, ne], [ne, north]]."""
    c = np.array([[cee, cne], [cne, cnn]])
    w, v = np.linalg.eigh(c)
    w = np.clip(w, 0, None)
    angle = np.degrees(np.arctan2(v[1, 1], v[0, 1]))
    return k * np.sqrt(w[1]), k * np.sqrt(w[0]), angle


def main(folder):
    with h5py.File(os.path.join(folder, "tracks.h5"), "r") as f:
        d = {k: np.array(f[k]) for k in f.keys()}
    with open(os.path.join(folder, "navigation.json")) as fh:
        summary = json.load(fh)
    lat0 = np.radians(np.nanmean(d["true_lat_deg"]))
    lon0 = np.nanmean(d["true_lon_deg"])
    lat0_deg = np.degrees(lat0)

    def to_km(lat, lon):
        east = np.radians(lon - lon0) * R_EARTH_M * np.cos(lat0) / 1000
        north = np.radians(lat - lat0_deg) * R_EARTH_M / 1000
        return east, north

    figs = []
    # 1. Tracks on the map.
    fig, ax = plt.subplots(figsize=(9, 8))
    e0, n0 = to_km(d["map_lat_deg"][0], d["map_lon_deg"][0])
    e1, n1 = to_km(d["map_lat_deg"][-1], d["map_lon_deg"][-1])
    im = ax.imshow(d["map_nT"], origin="lower", extent=[e0, e1, n0, n1], cmap="RdBu_r",
                   aspect="equal", alpha=0.8)
    fig.colorbar(im, ax=ax, label="anomaly map, nT")
    te, tn = to_km(d["true_lat_deg"], d["true_lon_deg"])
    ie, in_ = to_km(d["ins_lat_deg"], d["ins_lon_deg"])
    fe, fn = to_km(d["filter_lat_deg"], d["filter_lon_deg"])
    ax.plot(te, tn, "k-", lw=1.2, label="truth")
    ax.plot(ie, in_, "-", color="tab:orange", lw=1.0, label="INS alone")
    ax.plot(fe, fn, "-", color="tab:green", lw=1.0, label="filter")
    step = max(1, len(fe) // 25)
    for i in range(0, len(fe), step):
        a, b, ang = ellipse_axes(d["cov_north_m2"][i], d["cov_east_m2"][i],
                                 d["cov_north_east_m2"][i])
        ax.add_patch(Ellipse((fe[i], fn[i]), 2 * a / 1000, 2 * b / 1000, angle=ang, fill=False,
                             color="tab:green", lw=0.8))
    # NaN marks a sample without a true position (refused): the limits skip it.
    pad = 0.1 * max(np.nanmax(te) - np.nanmin(te), np.nanmax(tn) - np.nanmin(tn), 1.0)
    east = np.concatenate([te, ie, fe])
    north = np.concatenate([tn, in_, fn])
    ax.set_xlim(np.nanmin(east) - pad, np.nanmax(east) + pad)
    ax.set_ylim(np.nanmin(north) - pad, np.nanmax(north) + pad)
    ax.set_xlabel("east, km")
    ax.set_ylabel("north, km")
    ax.set_title("tracks on the map (filter with its 2-sigma ellipse, to scale)")
    ax.legend(loc="upper right")
    figs.append(("tracks.png", fig))

    # 2. Errors against the 2-sigma bound.
    t = d["t_s"] / 60
    err = np.hypot(d["error_north_m"], d["error_east_m"])
    ins_err = np.hypot(d["ins_error_north_m"], d["ins_error_east_m"])
    bound = 2 * np.sqrt(d["cov_north_m2"] + d["cov_east_m2"])
    fig, ax = plt.subplots(figsize=(11, 4))
    ax.semilogy(t, ins_err, color="tab:orange", lw=0.8, label="INS alone")
    ax.semilogy(t, err, color="tab:green", lw=0.8, label="filter")
    ax.semilogy(t, bound, "k--", lw=0.8, label="filter 2-sigma (horizontal)")
    ax.set_xlabel("time, min")
    ax.set_ylabel("horizontal error, m")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    figs.append(("errors.png", fig))

    # 3. Innovations.
    fig, ax = plt.subplots(figsize=(11, 3.5))
    sd = np.sqrt(d["innovation_var_nT2"])
    ax.plot(t, d["innovation_nT"], lw=0.5, color="tab:blue", label="innovation")
    ax.plot(t, 2 * sd, "k--", lw=0.7, label="+-2 predicted sigma")
    ax.plot(t, -2 * sd, "k--", lw=0.7)
    ax.set_xlabel("time, min")
    ax.set_ylabel("nT")
    ax.legend()
    figs.append(("innovations.png", fig))

    for name, fig in figs:
        fig.tight_layout()
        fig.savefig(os.path.join(folder, name), dpi=90)
        plt.close(fig)
    rows = [("measurement", summary.get("measurement", ""))]
    for k in ["drms_filter_m", "drms_ins_m", "drms_crlb_m", "nees_in_95_bounds",
              "innovation_mean_nT", "innovation_std_nT", "nis_mean",
              "measurement_minus_map_std_nT"]:
        if k in summary:  # a figure with nothing to compute it from is null: n/a
            rows.append((k, "n/a" if summary[k] is None else "%.4g" % summary[k]))
    table = "".join("<tr><td>%s</td><td>%s</td></tr>" % (html.escape(str(a)), html.escape(str(b)))
                    for a, b in rows)
    page = ("<html><head><meta charset='utf-8'><title>magcomp navigation</title></head><body>"
            "<h1>magcomp navigate: %s</h1><table border=1 cellpadding=3>%s</table>%s"
            "</body></html>") % (html.escape(summary.get("data", "")), table,
                                 "".join("<p><img src='%s'></p>" % n for n, _ in figs))
    with open(os.path.join(folder, "index.html"), "w") as fh:
        fh.write(page)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: magcomp_nav_report.py DIR (written by magcomp navigate --report DIR)")
    main(sys.argv[1])
