"""OpenCV's findChessboardCornersSB on the crops examples/chessboard_compare.rs wrote.

Reads the example's JSON lines (stdin), runs cv2.findChessboardCornersSB (pattern 7 x 5,
exhaustive + accuracy flags) on each crop and prints one JSON line per board in the same
shape, error under the best of the four orders a 7 x 5 grid allows. The pixel convention is
the same on both sides: pixel centres at integer coordinates.
"""
import json
import sys
import time

import cv2
import numpy as np


def best_error(found, truth):
    found = found.reshape(5, 7, 2)
    truth = np.asarray(truth).reshape(5, 7, 2)
    best = float("inf")
    for flip_rows in (False, True):
        for flip_cols in (False, True):
            f = found[::-1] if flip_rows else found
            f = f[:, ::-1] if flip_cols else f
            best = min(best, float(np.linalg.norm(f - truth, axis=2).mean()))
    return best


def main():
    out_dir = sys.argv[1]
    for line in sys.stdin:
        if not line.strip():
            continue
        ours = json.loads(line)
        grey = cv2.imread(f"{out_dir}/{ours['name']}.png", cv2.IMREAD_GRAYSCALE)
        flags = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
        started = time.perf_counter()
        ok, corners = cv2.findChessboardCornersSB(grey, (7, 5), flags=flags)
        seconds = time.perf_counter() - started
        error = best_error(corners.reshape(-1, 2), ours["truth"]) if ok else None
        print(json.dumps({
            "name": ours["name"], "camera": ours["camera"], "board": ours["board"],
            "tool": "opencv", "found": bool(ok), "mean_error_px": error, "seconds": seconds,
        }))


if __name__ == "__main__":
    main()
