"""Tables A3 and A5 of the UniCal supplementary from `rigcal eval --json` reports.

Usage: truck_table.py WORKDIR METHOD...  (reads WORKDIR/<method>-boards.json and
WORKDIR/<method>-street.json, and WORKDIR/times.txt). A camera's re-projection error is the mean
over the LiDARs its boards were measured against; a LiDAR's registration error the mean over
the LiDAR pairs it belongs to. "ref" rows are the ground truth measured the same way (the floor
the data allow).
"""

import json
import os
import sys


def load(path):
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return json.load(f)


def per_sensor(pairs, key, sensors, valid):
    """Mean of `key` over each sensor's valid pairs; a pair whose value is missing under this
    calibration (its boards are not re-found: the error exceeds the search window) marks the
    sensor with a dagger."""
    out = {}
    for s in sensors:
        mine = [p for p in pairs if s in (p["a"], p["b"]) and valid(p)]
        values = [p[key] for p in mine if p.get(key) is not None]
        lost = len(values) < len(mine)
        out[s] = (sum(values) / len(values) if values else None, lost)
    return out


# A camera-LiDAR pair measures a calibration only where it measures the ground truth well: the
# corner metric of the LiDAR's boards must be under this many pixels with the reference.
VALID_REFERENCE_PX = 10.0


def corner_pair_valid(p):
    return p.get("reference") is not None and p["reference"] < VALID_REFERENCE_PX


def fmt(v, digits):
    if isinstance(v, tuple):
        value, lost = v
        return ("–" if value is None else f"{value:.{digits}f}") + (" †" if lost else "")
    return "–" if v is None else f"{v:.{digits}f}"


def main():
    work, methods = sys.argv[1], sys.argv[2:]
    times = {}
    if os.path.exists(os.path.join(work, "times.txt")):
        for line in open(os.path.join(work, "times.txt")):
            name, seconds = line.split()
            times[name] = float(seconds)
    reports = {m: (load(os.path.join(work, f"{m}-boards.json")), load(os.path.join(work, f"{m}-street.json"))) for m in methods}
    first = next((r for r in reports.values() if r[0] and r[1]), None)
    if first is None:
        sys.exit("no reports")
    cameras = sorted({p["a"] for p in first[0]["corners_px"]} | {p["b"] for p in first[0]["corners_px"]})
    lidars = sorted({p["a"] for p in first[1]["registration_cm"]} | {p["b"] for p in first[1]["registration_cm"]})
    cameras = [c for c in cameras if c not in lidars]
    print(f"Table A3 layout: LiDAR–camera re-projection error (px at 1920 wide), held-out checkerboard collect; pairs whose ground truth measures under {VALID_REFERENCE_PX:.0f} px (the rest cannot tell calibrations apart); † a pair's boards not re-found under that calibration (error beyond the search window)\n")
    print("| method | " + " | ".join(cameras) + " | mean |")
    print("|---" * (len(cameras) + 2) + "|")
    rows = [("ref (ground truth)", first[0], "reference")] + [(m, reports[m][0], "calibration") for m in methods]
    for name, rep, key in rows:
        if rep is None:
            continue
        v = per_sensor(rep["corners_px"], key, cameras, corner_pair_valid)
        got = [x[0] for x in v.values() if x[0] is not None]
        mean = sum(got) / len(got) if got else None
        print(f"| {name} | " + " | ".join(fmt(v[c], 2) for c in cameras) + f" | {fmt(mean, 2)} |")
    print("\nTable A5 layout: LiDAR–LiDAR point-to-plane registration error (cm), held-out street collect\n")
    print("| method | " + " | ".join(lidars) + " | mean |")
    print("|---" * (len(lidars) + 2) + "|")
    rows = [("ref (ground truth)", first[1], "reference")] + [(m, reports[m][1], "calibration") for m in methods]
    for name, rep, key in rows:
        if rep is None:
            continue
        v = per_sensor(rep["registration_cm"], key, lidars, lambda p: True)
        got = [x[0] for x in v.values() if x[0] is not None]
        mean = sum(got) / len(got) if got else None
        print(f"| {name} | " + " | ".join(fmt(v[l], 2) for l in lidars) + f" | {fmt(mean, 2)} |")
    print("\nPose error against the ground truth (mean over sensors, after aligning the root LiDAR) and run time\n")
    print("| method | LiDAR rotation | LiDAR translation | camera rotation | camera translation | calibrate time |")
    print("|---|---|---|---|---|---|")
    for m in methods:
        rep = reports[m][0] or reports[m][1]
        if rep is None:
            continue
        def mean(kind, field):
            xs = [p[field] for p in rep["poses"] if (p["sensor"] in lidars) == (kind == "lidar") and p["sensor"] != rep["root"]]
            return sum(xs) / len(xs) if xs else None
        lr, lt = mean("lidar", "rotation_deg"), mean("lidar", "translation_m")
        cr, ct = mean("camera", "rotation_deg"), mean("camera", "translation_m")
        t = times.get(m)
        print(f"| {m} | {fmt(lr, 3)}° | {fmt(lt and lt * 100, 1)} cm | {fmt(cr, 3)}° | {fmt(ct and ct * 100, 1)} cm | {fmt(t, 0)} s |")


if __name__ == "__main__":
    main()
