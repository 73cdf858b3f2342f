"""The official Python MCAP reader (mcap + mcap-ros2-support) doing the work of rigcal's ingest
benchmark: decode every message of a ROS 2 MCAP, unpack PointCloud2 points into arrays and, at the
"full" level, decode every CompressedImage to RGB pixels. Prints one JSON line of timings.

    python3 benches/ingest_reference.py LOG.mcap
Needs: pip install mcap mcap-ros2-support numpy pillow
"""
import io
import json
import sys
import time

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from PIL import Image

DTYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


def points(msg):
    """PointCloud2 -> (N,3) float32 xyz and (N,) float32 intensity, as a numpy user would."""
    endian = ">" if msg.is_bigendian else "<"
    dtype = np.dtype(
        {
            "names": [f.name for f in msg.fields],
            "formats": [endian + DTYPES[f.datatype] for f in msg.fields],
            "offsets": [f.offset for f in msg.fields],
            "itemsize": msg.point_step,
        }
    )
    n = msg.width * msg.height
    arr = np.frombuffer(bytes(msg.data), dtype=dtype, count=n)
    xyz = np.stack([arr["x"], arr["y"], arr["z"]], axis=1).astype(np.float32)
    intensity = arr["intensity"].astype(np.float32) if "intensity" in arr.dtype.names else None
    return xyz, intensity


def run(path, decode_pixels):
    t0 = time.perf_counter()
    n_msgs = n_points = n_pixels = 0
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, msg in reader.iter_decoded_messages():
            n_msgs += 1
            if schema.name == "sensor_msgs/msg/PointCloud2":
                xyz, _ = points(msg)
                n_points += len(xyz)
            elif schema.name == "sensor_msgs/msg/CompressedImage" and decode_pixels:
                rgb = np.asarray(Image.open(io.BytesIO(bytes(msg.data))).convert("RGB"))
                n_pixels += rgb.shape[0] * rgb.shape[1]
    return {
        "secs": time.perf_counter() - t0,
        "messages": n_msgs,
        "points": n_points,
        "pixels": n_pixels,
    }


def main():
    path = sys.argv[1]
    reps = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    out = {}
    for level, pixels in (("messages", False), ("full", True)):
        runs = [run(path, pixels) for _ in range(reps)]
        best = min(runs, key=lambda r: r["secs"])
        out[level] = best
    print(json.dumps(out))


if __name__ == "__main__":
    main()
