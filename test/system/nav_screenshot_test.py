#!/usr/bin/env python3
"""Screenshot test of the navigation view: `roslaunch magcomp navigate.launch bag:=... rviz:=true`
under Xvfb shows what a person expects: the anomaly map, the truth (blue), INS (orange) and
filter (green) tracks, and the navigator publishes its status.
Usage: nav_screenshot_test.py DATA_DIR OUT.png   (DATA_DIR holds nav_flight.bag, nav_model.yaml,
nav_flight.map.h5). Exit 0 when every check passes; prints one line per check.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from screenshot_test import capture, count, pixels  # noqa: E402


def main():
    data_dir, out_png = sys.argv[1], sys.argv[2]
    ok = True
    status = capture(["navigate.launch", "bag:=" + data_dir + "/nav_flight.bag",
                      "model:=" + data_dir + "/nav_model.yaml",
                      "map:=" + data_dir + "/nav_flight.map.h5", "rviz:=true", "rate:=20"],
                     out_png, "1400x1000x24", 30,
                     ["/usr/bin/python3", "/usr/bin/rostopic", "echo", "-n", "1", "/magcomp/nav/status"])
    used = "measurement_used: True" in status
    print("navigator status published, measurement used: %s" % ("yes" if used else "no"))
    ok &= used
    w, h, data = pixels(out_png)
    x0 = 360  # right of the displays panel
    orange = count(w, h, data, x0, w, lambda r, g, b: r > 220 and 100 < g < 160 and b < 60)
    green = count(w, h, data, x0, w, lambda r, g, b: g > 130 and r < 90 and b < 90)
    blue = count(w, h, data, x0, w, lambda r, g, b: b > 150 and r < 80 and 90 < g < 150)
    grey = count(w, h, data, x0, w, lambda r, g, b: abs(r - g) < 6 and abs(g - b) < 6 and 130 < r < 235)
    print("rviz: %d orange (INS), %d green (filter), %d blue (truth), %d grey (map) pixels "
          "(sampled 1 in 4)" % (orange, green, blue, grey))
    ok &= orange > 30 and green > 30 and blue > 30 and grey > 2000
    print("navigation screenshot test: %s (%s)" % ("PASS" if ok else "FAIL", out_png))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
