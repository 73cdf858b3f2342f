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


def per_sensor(pairs, key, sensors, side):
    out = {}
    for s in sensors:
        values = [p[key] for p in pairs if p.get(key) is not None and s in (p["a"], p["b"]) and (side is None or p[side] == s)]
        out[s] = sum(values) / len(values) if values else None
    return out


def fmt(v, digits):
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
    print("Table A3 layout: LiDAR–camera re-projection error (px at 1920 wide), held-out checkerboard collect\n")
    print("| method | " + " | ".join(cameras) + " | mean |")
    print("|---" * (len(cameras) + 2) + "|")
    rows = [("ref (ground truth)", first[0], "reference")] + [(m, reports[m][0], "calibration") for m in methods]
    for name, rep, key in rows:
        if rep is None:
            continue
        v = per_sensor(rep["corners_px"], key, cameras, None)
        got = [x for x in v.values() if x is not None]
        mean = sum(got) / len(got) if got else None
        print(f"| {name} | " + " | ".join(fmt(v[c], 2) for c in cameras) + f" | {fmt(mean, 2)} |")
    print("\nTable A5 layout: LiDAR–LiDAR point-to-plane registration error (cm), held-out street collect\n")
    print("| method | " + " | ".join(lidars) + " | mean |")
    print("|---" * (len(lidars) + 2) + "|")
    rows = [("ref (ground truth)", first[1], "reference")] + [(m, reports[m][1], "calibration") for m in methods]
    for name, rep, key in rows:
        if rep is None:
            continue
        v = per_sensor(rep["registration_cm"], key, lidars, None)
        got = [x for x in v.values() if x is not None]
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
