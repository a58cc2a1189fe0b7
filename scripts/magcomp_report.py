#!/usr/bin/python3
"""magcomp report: turns `magcomp evaluate --report DIR` output (series.h5, evaluation.json) into
DIR/index.html with PNG plots: model vs measurement vs reference over time with the error below,
error by line / flight condition / heading sector, the error along the track, the error's spectrum
against the aircraft signal's, the error against the auxiliary channels, and for a model with a
trained network, what it leans on (evaluate --explain) and whether its gain carries over."""
import html
import json
import os
import sys

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy import signal, stats  # noqa: E402

CONDITIONS = ["straight_level", "turn", "climb_descent", "maneuver_pitch", "maneuver_roll",
              "maneuver_yaw"]


def line_demeaned(err, line):
    out = np.full_like(err, np.nan)
    for value in np.unique(line[np.isfinite(line)]):
        m = (line == value) & np.isfinite(err)
        if m.any():
            out[m] = err[m] - err[m].mean()
    return out


def main(folder):
    s = {k: v[()] for k, v in h5py.File(os.path.join(folder, "series.h5"), "r").items()}
    ev = json.load(open(os.path.join(folder, "evaluation.json")))
    t = (s["tt"] - s["tt"][0]) / 60.0
    line = s["line"]
    err = line_demeaned(s["error"], line)
    base = line_demeaned(s["error_baseline"], line) if "error_baseline" in s else None
    figs = []

    def save(fig, name, caption):
        fig.tight_layout()
        fig.savefig(os.path.join(folder, name), dpi=90)
        plt.close(fig)
        figs.append((name, caption))

    # 1. Model vs measurement vs reference, error below.
    fig, ax = plt.subplots(2, 1, figsize=(12, 6.5), sharex=True)
    ax[0].plot(t, s["measured"], lw=0.6, label="measured (uncompensated)")
    ax[0].plot(t, s["compensated"], lw=0.6, label="compensated (model)")
    ax[0].plot(t, s["truth"], lw=0.6, label="reference: " + ev.get("truth", "truth"))
    ax[0].set_ylabel("field, nT")
    ax[0].legend(loc="upper right", fontsize=8)
    if base is not None:
        ax[1].plot(t, base, lw=0.5, color="0.6", label="baseline model")
    ax[1].plot(t, err, lw=0.5, color="C3", label="this model")
    ax[1].set_ylabel("error, nT (line means removed)")
    ax[1].set_xlabel("minutes from start")
    ax[1].legend(loc="upper right", fontsize=8)
    edges = np.where(np.diff(line) != 0)[0]
    for a in ax:
        for e in edges:
            a.axvline(t[e], color="0.85", lw=0.5, zorder=0)
    save(fig, "timeseries.png", "Model, measurement and reference over time (grey: line changes); "
         "the error below.")

    # 2. Error by line, condition, heading.
    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    names = ["%.2f" % r["line"] for r in ev["per_line"]]
    x = np.arange(len(names))
    # null: a line of one sample has no spread (no bar)
    std = lambda rows: [np.nan if r["std_nT"] is None else r["std_nT"] for r in rows]
    ax[0].bar(x, std(ev["per_line"]), color="C3", label="this model")
    if "baseline" in ev:
        ax[0].bar(x, std(ev["baseline"]["per_line"]), color="0.7", alpha=0.5, label="baseline")
        ax[0].legend(fontsize=8)
    ax[0].set_xticks(x, names, rotation=60, fontsize=7)
    ax[0].set_ylabel("error std, nT")
    ax[0].set_title("by line")
    for a, key, title in [(ax[1], "per_condition", "by flight condition"),
                          (ax[2], "per_heading", "by heading sector")]:
        groups = ev.get(key, [])
        xx = np.arange(len(groups))
        a.bar(xx, [g["std_nT"] for g in groups], color="C3")
        if "baseline" in ev:
            a.bar(xx, [g["std_nT"] for g in ev["baseline"].get(key, [])], color="0.7", alpha=0.5)
        a.set_xticks(xx, [g["name"] for g in groups], rotation=45, fontsize=8)
        a.set_title(title)
    save(fig, "groups.png", "Error std (line means removed) per line, per flight condition and per "
         "heading sector; grey: the baseline model.")

    # 3. Where does it fail: the error along the track.
    xk, yk = ("utm_x", "utm_y") if "utm_x" in s else ("lon", "lat")
    fig, ax = plt.subplots(figsize=(8, 7))
    lim = np.nanpercentile(np.abs(err), 99) or 1.0
    sc = ax.scatter(s[xk], s[yk], c=err, s=2, cmap="coolwarm", vmin=-lim, vmax=lim)
    fig.colorbar(sc, ax=ax, label="error, nT")
    ax.set_xlabel(xk + " (m)" if xk == "utm_x" else xk)
    ax.set_ylabel(yk + " (m)" if yk == "utm_y" else yk)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("error along the track")
    save(fig, "map.png", "The error along the track: where does the model fail?")

    # 4. At which frequencies: Welch spectra on the longest finite stretch.
    finite = np.isfinite(s["error"]) & np.isfinite(s["measured"]) & np.isfinite(s["truth"])
    runs = np.split(np.arange(len(finite)), np.where(np.diff(finite.astype(int)) != 0)[0] + 1)
    run = max((r for r in runs if finite[r[0]]), key=len)
    fs = 1.0 / np.median(np.diff(s["tt"]))
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for series, label, color in [(s["measured"] - s["truth"], "aircraft signal (measured - ref)", "C0"),
                                 (s["error"], "error (this model)", "C3")] + (
            [(s["error_baseline"], "error (baseline)", "0.6")] if base is not None else []):
        f, p = signal.welch(signal.detrend(series[run]), fs=fs, nperseg=min(2048, len(run)))
        ax.loglog(f[1:], np.sqrt(p[1:]), label=label, color=color, lw=0.9)
    ax.axvspan(0.1, 0.9, color="0.93", zorder=0, label="TL calibration band")
    ax.set_xlabel("frequency, Hz")
    ax.set_ylabel("amplitude spectral density, nT/sqrt(Hz)")
    ax.legend(fontsize=8)
    save(fig, "spectrum.png", "At which frequencies: the error's spectrum against the aircraft "
         "signal's (shaded: the 0.1-0.9 Hz band TL is calibrated in).")

    # 5. When a current switches, does the error jump? The channels most associated with it.
    channels = [k for k in s if k.startswith(("cur_", "vol_"))]
    scored = []
    ok = np.isfinite(err)
    for k in channels:
        v = s[k]
        m = ok & np.isfinite(v)
        if m.sum() > 100 and np.ptp(v[m]) > 0:
            rho = stats.spearmanr(v[m][::5], err[m][::5]).correlation
            scored.append((abs(rho) if np.isfinite(rho) else 0.0, rho, k))
    scored.sort(reverse=True)
    top = scored[:6]
    if top:
        fig, axs = plt.subplots(2, 3, figsize=(13, 7))
        for a, (_, rho, k) in zip(axs.ravel(), top):
            v = s[k]
            m = ok & np.isfinite(v)
            a.plot(v[m][::3], err[m][::3], ".", ms=1, alpha=0.3, color="C3")
            q = np.unique(np.quantile(v[m], np.linspace(0, 1, 21)))
            if len(q) > 2:
                idx = np.digitize(v[m], q[1:-1])
                means = [err[m][idx == i].mean() if (idx == i).any() else np.nan for i in range(len(q) - 1)]
                a.plot(0.5 * (q[1:] + q[:-1]), means, "k-", lw=1.5)
            a.set_title("%s  (Spearman %.2f)" % (k, rho), fontsize=9)
            a.set_xlabel(k)
            a.set_ylabel("error, nT")
        save(fig, "channels.png", "The error against the auxiliary channels most associated with it "
             "(black: binned mean). A step with a current means a current-carrying source.")

    # 4. What a network leans on (evaluate --explain): each input's share, largest first.
    att = ev.get("attribution")
    if att and att.get("inputs"):
        inputs = att["inputs"][:15]
        fig, a = plt.subplots(figsize=(9, 0.32 * len(inputs) + 1.3))
        a.barh([x["feature"] for x in inputs][::-1], [100 * x["share"] for x in inputs][::-1],
               color="C0")
        a.set_xlabel("share of the rise in the network's error when the input is shuffled, %")
        a.set_title("what the network leans on (%s, %d samples)" % (att["method"], att["samples"]),
                    fontsize=10)
        save(fig, "attribution.png", "Each input's share of what the network's prediction rests on "
             "(%s on this flight; correlated inputs share an effect)." % att["method"])

    rows = "".join("<tr><td>%.2f</td><td>%d</td><td>%.3f</td><td>%s</td></tr>" % (
        r["line"], r["n"], r["rmse_nT"], "n/a" if r["std_nT"] is None else "%.3f" % r["std_nT"])
        for r in ev["per_line"])
    groups = "".join("<tr><td>%s</td><td>%d</td><td>%.3f</td></tr>" % (g["name"], g["n"], g["std_nT"])
                     for g in ev.get("per_condition", []) + ev.get("per_heading", []))
    base_line = ""
    if "baseline" in ev:
        base_line = "<p>Baseline model <code>%s</code>: std %.3f nT &rarr; this model: <b>%.3f nT</b>.</p>" % (
            html.escape(ev["baseline"]["model"]), ev["baseline"]["std_nT"], ev["std_nT"])
    if "network_gain" in ev:
        base_line += "<p>%s.</p>" % html.escape(ev["network_gain"]["verdict"])
    body = "".join('<figure><img src="%s"><figcaption>%s</figcaption></figure>' % (n, html.escape(c))
                   for n, c in figs)
    page = f"""<!doctype html><html><head><meta charset="utf-8"><title>magcomp evaluation</title>
<style>body{{font-family:sans-serif;max-width:1200px;margin:auto}} img{{max-width:100%}}
table{{border-collapse:collapse;display:inline-block;vertical-align:top;margin-right:2em}}
td,th{{border:1px solid #ccc;padding:2px 8px;text-align:right}}</style></head><body>
<h1>magcomp evaluation</h1>
<p>Data <code>{html.escape(ev['data'])}</code>, model <code>{html.escape(ev['model'])}</code>
(terms: {html.escape(', '.join(ev.get('terms', [])))}), reference <code>{html.escape(ev['truth'])}</code>.</p>
<p>Error std (line means removed): <b>{ev['std_nT']:.3f} nT</b>, raw RMSE {ev['rmse_nT']:.3f} nT on {ev['n']} samples.</p>
{base_line}
<table><tr><th>line</th><th>n</th><th>rmse_nT</th><th>std_nT</th></tr>{rows}</table>
<table><tr><th>condition / heading</th><th>n</th><th>std_nT</th></tr>{groups}</table>
{body}</body></html>"""
    with open(os.path.join(folder, "index.html"), "w") as f:
        f.write(page)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: magcomp_report.py DIR (written by magcomp evaluate --report DIR)")
    main(sys.argv[1])
