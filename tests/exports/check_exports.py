#!/usr/bin/env python3
"""Check `rigcal export` with the parsers other tools use.

Every format is written from one native calibration file (tests/exports/rig.yaml unless told
otherwise) and read back by a real, independent parser: cv2.FileStorage for OpenCV YAML,
yourdfpy (which resolves the URDF's frames) for URDF, the official mcap reader with ROS 2
decoding (mcap-ros2-support) for the MCAP, xml.etree for the launch file, shlex for the
commands, json for nuScenes and PyYAML for the rest. The transforms read back must be the
native file's `vehicle_from_sensor` (or the transform the format defines from them) to 1e-9.

usage: check_exports.py RIGCAL_BINARY [RIG.yaml] [WORKDIR]
Prints one line per check and closes with "N passed, M failed"; exits non-zero on a failure.
"""

import json
import math
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

import numpy as np
import yaml

TOL = 1e-9
results = []


def check(name, ok, detail=""):
    results.append((name, bool(ok)))
    print(("ok    " if ok else "FAIL  ") + name + (f": {detail}" if detail and not ok else ""))


def quat_xyzw_to_matrix(q):
    x, y, z, w = q
    n = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def rigid(rotation, translation):
    t = np.eye(4)
    t[:3, :3] = rotation
    t[:3, 3] = translation
    return t


def rpy_to_matrix(r, p, y):
    """URDF fixed-axis roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


# REP-103: body (x forward, y left, z up) from optical (x right, y down, z forward).
BODY_FROM_OPTICAL = rigid(rpy_to_matrix(-math.pi / 2, 0, -math.pi / 2), [0, 0, 0])


def close(a, b, tol=TOL):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and np.max(np.abs(a - b)) < tol


def body_link(frame):
    for suffix in ("_optical_frame", "_optical_link", "_optical"):
        if frame.endswith(suffix):
            return frame[: -len(suffix)] + "_link"
    return frame + "_link"


class Rig:
    def __init__(self, path):
        with open(path) as f:
            doc = yaml.safe_load(f)
        self.vehicle = doc["vehicle_frame"]
        self.sensors = []
        for s in doc["sensors"]:
            e = s["vehicle_from_sensor"]
            s["T"] = rigid(quat_xyzw_to_matrix(e["rotation_xyzw"]), e["translation_m"])
            s.setdefault("frame_id", s["name"])
            self.sensors.append(s)

    def by_name(self, name):
        return next(s for s in self.sensors if s["name"] == name)

    def cameras(self):
        return [s for s in self.sensors if s["kind"] == "camera"]

    def lidars(self):
        return [s for s in self.sensors if s["kind"] == "lidar"]


def k_of(cam):
    c = cam["camera"]
    return np.array([[c["fx"], 0, c["cx"]], [0, c["fy"], c["cy"]], [0, 0, 1.0]])


def ros_distortion(cam):
    c = cam["camera"]
    model = c["model"]
    n = {"pinhole": 5, "plumb_bob": 5, "rational_polynomial": 8, "equidistant": 4}[model]
    d = list(c.get("distortion", [])) + [0.0] * n
    return ("plumb_bob" if model == "pinhole" else model), d[: max(n, len(c.get("distortion", [])))]


def export(binary, rig_path, fmt, out, *extra):
    cmd = [binary, "export", rig_path, "--format", fmt, "--out", out, *extra]
    p = subprocess.run(cmd, capture_output=True, text=True)
    check(f"{fmt}: rigcal export exits 0", p.returncode == 0, p.stderr.strip())
    return p.returncode == 0


def check_native(rig, out):
    with open(out) as f:
        doc = yaml.safe_load(f)
    back = {s["name"]: s for s in doc["sensors"]}
    for s in rig.sensors:
        e = back[s["name"]]["vehicle_from_sensor"]
        t = rigid(quat_xyzw_to_matrix(e["rotation_xyzw"]), e["translation_m"])
        check(f"native: {s['name']} vehicle_from_sensor", close(t, s["T"]))
        check(f"native: {s['name']} matrix is the same transform", close(np.array(e["matrix"]), s["T"]))


def check_camera_info(rig, out):
    for cam in rig.cameras():
        with open(os.path.join(out, cam["name"] + ".yaml")) as f:
            ci = yaml.safe_load(f)
        model, d = ros_distortion(cam)
        k = np.array(ci["camera_matrix"]["data"]).reshape(3, 3)
        p = np.array(ci["projection_matrix"]["data"]).reshape(3, 4)
        ok = (
            close(k, k_of(cam))
            and ci["distortion_model"] == model
            and close(ci["distortion_coefficients"]["data"], d)
            and ci["distortion_coefficients"]["cols"] == len(d)
            and close(p[:, :3], k_of(cam))
            and (ci["image_width"], ci["image_height"]) == (cam["camera"]["width"], cam["camera"]["height"])
            and ci["camera_name"] == cam["name"]
        )
        check(f"camera-info: {cam['name']} K, D, model, P, size", ok, str(ci))


def check_mcap(rig, out):
    from mcap_ros2.reader import read_ros2_messages

    tfs, infos = {}, {}
    for m in read_ros2_messages(out):
        if m.channel.topic == "/tf_static":
            for t in m.ros_msg.transforms:
                tr, q = t.transform.translation, t.transform.rotation
                tfs[(t.header.frame_id, t.child_frame_id)] = rigid(
                    quat_xyzw_to_matrix([q.x, q.y, q.z, q.w]), [tr.x, tr.y, tr.z]
                )
        elif m.schema.name == "sensor_msgs/msg/CameraInfo":
            infos[m.ros_msg.header.frame_id] = m.ros_msg
    for s in rig.sensors:
        t = tfs.get((rig.vehicle, s["frame_id"]))
        check(f"mcap: /tf_static {rig.vehicle} -> {s['frame_id']} is vehicle_from_sensor", t is not None and close(t, s["T"]))
    for cam in rig.cameras():
        info = infos.get(cam["frame_id"])
        model, d = ros_distortion(cam)
        ok = (
            info is not None
            and close(np.array(info.k).reshape(3, 3), k_of(cam))
            and info.distortion_model == model
            and close(list(info.d), d)
            and (info.width, info.height) == (cam["camera"]["width"], cam["camera"]["height"])
        )
        check(f"mcap: CameraInfo of {cam['frame_id']}", ok)


def check_urdf(rig, out):
    import yourdfpy

    robot = yourdfpy.URDF.load(out, build_scene_graph=True, load_meshes=False, build_collision_scene_graph=False)
    for s in rig.sensors:
        # yourdfpy: get_transform(frame_to, frame_from) is the pose of frame_to in frame_from.
        t = robot.get_transform(frame_to=s["frame_id"], frame_from=rig.vehicle)
        check(f"urdf: {rig.vehicle} -> {s['frame_id']} resolves to vehicle_from_sensor", close(t, s["T"]), str(t))
    for cam in rig.cameras():
        body = robot.get_transform(frame_to=body_link(cam["frame_id"]), frame_from=rig.vehicle)
        optical_axis_in_vehicle = cam["T"][:3, 2]
        check(
            f"urdf: {body_link(cam['frame_id'])} is REP-103 (x forward = optical z)",
            close(body[:3, 0], optical_axis_in_vehicle) and close(body, cam["T"] @ np.linalg.inv(BODY_FROM_OPTICAL)),
        )


def static_tf_args(words):
    get = lambda flag: words[words.index(flag) + 1]
    q = [float(get(f)) for f in ("--qx", "--qy", "--qz", "--qw")]
    t = [float(get(f)) for f in ("--x", "--y", "--z")]
    return get("--frame-id"), get("--child-frame-id"), rigid(quat_xyzw_to_matrix(q), t)


def check_static_tf(rig, parsed, fmt):
    found = {(p, c): t for p, c, t in parsed}
    for s in rig.sensors:
        t = found.get((rig.vehicle, s["frame_id"]))
        check(f"{fmt}: {rig.vehicle} -> {s['frame_id']} is vehicle_from_sensor", t is not None and close(t, s["T"]))


def check_script(rig, out):
    parsed = []
    with open(out) as f:
        for line in f:
            words = shlex.split(line, comments=True)
            if words[:3] == ["ros2", "run", "tf2_ros"]:
                parsed.append(static_tf_args(words[4:]))
    check_static_tf(rig, parsed, "ros2-static-tf")
    p = subprocess.run(["sh", "-n", out], capture_output=True, text=True)
    check("ros2-static-tf: valid POSIX shell (sh -n)", p.returncode == 0, p.stderr)


def check_launch(rig, out):
    root = ET.parse(out).getroot()
    nodes = root.findall("node")
    check("ros2-launch: every node is tf2_ros static_transform_publisher", all(n.get("pkg") == "tf2_ros" and n.get("exec") == "static_transform_publisher" for n in nodes))
    check_static_tf(rig, [static_tf_args(shlex.split(n.get("args"))) for n in nodes], "ros2-launch")


def check_autoware(rig, out):
    with open(out) as f:
        doc = yaml.safe_load(f)
    root = doc["sensor_kit_base_link"]
    for s in rig.sensors:
        camera = s["kind"] == "camera"
        if camera:
            stem = body_link(s["frame_id"])
            key = stem if stem.endswith("/camera_link") else stem[: -len("_link")] + "/camera_link"
        else:
            key = s["frame_id"] if s["frame_id"].endswith("_base_link") else s["frame_id"] + "_base_link"
        e = root[key]
        t = rigid(rpy_to_matrix(e["roll"], e["pitch"], e["yaw"]), [e["x"], e["y"], e["z"]])
        expected = s["T"] @ np.linalg.inv(BODY_FROM_OPTICAL) if camera else s["T"]
        check(f"autoware: {key} is vehicle_from_{'camera_body' if camera else 'lidar'}", close(t, expected))


def check_opencv(rig, out, lidar):
    import cv2

    ref = rig.by_name(lidar)
    for cam in rig.cameras():
        fs = cv2.FileStorage(os.path.join(out, cam["name"] + ".yaml"), cv2.FILE_STORAGE_READ)
        ext = fs.getNode("CameraExtrinsicMat").mat()
        k = fs.getNode("CameraMat").mat()
        d = fs.getNode("DistCoeff").mat()
        size = fs.getNode("ImageSize")
        size = [int(size.at(i).real()) for i in range(size.size())]
        model = fs.getNode("DistModel").string()
        _, dist = ros_distortion(cam)
        expected = np.linalg.inv(ref["T"]) @ cam["T"]
        check(f"opencv: {cam['name']} CameraExtrinsicMat is {lidar}_from_camera", ext is not None and close(ext, expected))
        check(
            f"opencv: {cam['name']} CameraMat, DistCoeff, ImageSize, DistModel",
            close(k, k_of(cam)) and close(d.ravel(), dist) and size == [cam["camera"]["width"], cam["camera"]["height"]] and model == ros_distortion(cam)[0],
        )
        fs.release()


def check_kalibr(rig, out, names):
    with open(out) as f:
        doc = yaml.safe_load(f)
    cams = [rig.by_name(n) for n in names]
    cn_from_c0 = np.eye(4)
    for i, cam in enumerate(cams):
        entry = doc[f"cam{i}"]
        if i > 0:
            cn_from_c0 = np.array(entry["T_cn_cnm1"]) @ cn_from_c0
        expected = np.linalg.inv(cam["T"]) @ cams[0]["T"]
        c = cam["camera"]
        check(
            f"kalibr: cam{i} ({cam['name']}) chain and intrinsics",
            close(cn_from_c0, expected) and close(entry["intrinsics"], [c["fx"], c["fy"], c["cx"], c["cy"]]) and entry["resolution"] == [c["width"], c["height"]],
        )
        # Kalibr's names: radtan is plumb_bob's k1 k2 p1 p2 (k3 must be 0), equidistant the same
        # four Kannala-Brandt coefficients, a pinhole has none.
        d = list(c.get("distortion", [])) + [0.0] * 5
        model, coeffs = {
            "pinhole": ("none", []),
            "plumb_bob": ("radtan", d[:4]),
            "equidistant": ("equidistant", d[:4]),
        }[c["model"]]
        check(
            f"kalibr: cam{i} ({cam['name']}) distortion is {model} {coeffs}",
            entry["camera_model"] == "pinhole" and entry["distortion_model"] == model and close(entry["distortion_coeffs"], coeffs) if coeffs else entry["distortion_model"] == model,
        )


def check_kitti(rig, out, camera_names, lidar):
    calib = {}
    with open(out) as f:
        for line in f:
            key, values = line.split(":", 1)
            calib[key] = np.array([float(v) for v in values.split()])
    tr = np.vstack([calib["Tr_velo_to_cam"].reshape(3, 4), [0, 0, 0, 1]])
    r0 = np.eye(4)
    r0[:3, :3] = calib["R0_rect"].reshape(3, 3)
    velo = rig.by_name(lidar)
    point = np.array([12.0, -1.5, 0.7, 1.0])  # in the LiDAR frame
    check("kitti: exactly P0 P1 P2 P3 R0_rect Tr_velo_to_cam Tr_imu_to_velo, in order", list(calib) == ["P0", "P1", "P2", "P3", "R0_rect", "Tr_velo_to_cam", "Tr_imu_to_velo"])
    # The reference camera is P0 and P2, the next P3, the one after P1 (free slots repeat it).
    ref = camera_names[0]
    slots = [camera_names[2] if len(camera_names) > 2 else ref, ref, camera_names[1] if len(camera_names) > 1 else ref]
    for i, name in [(0, ref), (1, slots[0]), (2, ref), (3, slots[2])]:
        cam = rig.by_name(name)
        y = calib[f"P{i}"].reshape(3, 4) @ r0 @ tr @ point
        in_cam = np.linalg.inv(cam["T"]) @ velo["T"] @ point
        expected = k_of(cam) @ in_cam[:3]
        check(f"kitti: P{i} · R0_rect · Tr_velo_to_cam projects like {name}", close(y[:2] / y[2], expected[:2] / expected[2], 1e-6))
    imu = np.vstack([calib["Tr_imu_to_velo"].reshape(3, 4), [0, 0, 0, 1]])
    check("kitti: Tr_imu_to_velo is lidar_from_vehicle", close(imu, np.linalg.inv(velo["T"])))


def check_nuscenes(rig, out):
    with open(out) as f:
        records = {r["channel"]: r for r in json.load(f)}
    for s in rig.sensors:
        r = records[s["name"]]
        w, x, y, z = r["rotation"]
        t = rigid(quat_xyzw_to_matrix([x, y, z, w]), r["translation"])
        k_ok = close(r["camera_intrinsic"], k_of(s)) if s["kind"] == "camera" else r["camera_intrinsic"] == []
        check(f"nuscenes: {s['name']} ego_from_sensor (w, x, y, z) and intrinsics", close(t, s["T"]) and k_ok and len(r["token"]) == 32)


def main():
    if len(sys.argv) < 2:
        print(__doc__)
        return 2
    binary = sys.argv[1]
    here = os.path.dirname(os.path.abspath(__file__))
    rig_path = sys.argv[2] if len(sys.argv) > 2 else os.path.join(here, "rig.yaml")
    if len(sys.argv) > 3:
        return run_checks(binary, rig_path, sys.argv[3])
    # No work folder given: a scratch folder, removed however the checks end.
    work = tempfile.mkdtemp(prefix="rigcal-exports-")
    try:
        return run_checks(binary, rig_path, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def run_checks(binary, rig_path, work):
    rig = Rig(rig_path)
    lidar = rig.lidars()[-1]["name"]
    out = lambda name: os.path.join(work, name)

    if export(binary, rig_path, "native", out("native.yaml")):
        check_native(rig, out("native.yaml"))
    if export(binary, rig_path, "camera-info", out("camera_info")):
        check_camera_info(rig, out("camera_info"))
    if export(binary, rig_path, "mcap", out("calibration.mcap")):
        check_mcap(rig, out("calibration.mcap"))
    if export(binary, rig_path, "urdf", out("rig.urdf")):
        check_urdf(rig, out("rig.urdf"))
    if export(binary, rig_path, "ros2-static-tf", out("static_tf.sh")):
        check_script(rig, out("static_tf.sh"))
    if export(binary, rig_path, "ros2-launch", out("static_tf.launch.xml")):
        check_launch(rig, out("static_tf.launch.xml"))
    if export(binary, rig_path, "autoware", out("sensor_kit_calibration.yaml")):
        check_autoware(rig, out("sensor_kit_calibration.yaml"))
    if export(binary, rig_path, "opencv", out("opencv"), "--lidar", lidar):
        check_opencv(rig, out("opencv"), lidar)
    # Kalibr has no rational_polynomial model; KITTI has no distortion: subsets.
    kalibr_cams = [c["name"] for c in rig.cameras() if c["camera"]["model"] != "rational_polynomial"]
    if export(binary, rig_path, "kalibr", out("camchain.yaml"), "--sensors", ",".join(kalibr_cams)):
        check_kalibr(rig, out("camchain.yaml"), kalibr_cams)
    kitti_cams = [c["name"] for c in rig.cameras() if not any(c["camera"].get("distortion", []))]
    sensors = ",".join(kitti_cams + [lidar])
    if export(binary, rig_path, "kitti", out("calib.txt"), "--sensors", sensors, "--lidar", lidar):
        check_kitti(rig, out("calib.txt"), kitti_cams, lidar)
    if export(binary, rig_path, "nuscenes", out("calibrated_sensor.json")):
        check_nuscenes(rig, out("calibrated_sensor.json"))

    failed = sum(1 for _, ok in results if not ok)
    print(f"exports: {len(results) - failed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
