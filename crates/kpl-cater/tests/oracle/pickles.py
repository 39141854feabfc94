"""Writes perception pickles the way OPNet's scripts do, for kpl-cater's pickle test.

- `detector_p<N>.pkl`: as `preprocess_perception_main.py` (per frame numpy int arrays of boxes and
  labels, `astype(np.int)`), with pickle protocol N (OPNet ran Python 3.7: protocol 3 by default,
  HIGHEST_PROTOCOL 4; Python 3.8+ adds 5);
- `perfect.pkl`: as `get_perfect_perception_and_visible_snitch_ratio.py` (boxes as lists of Python
  ints, labels as numpy arrays), default protocol;
- `float32.pkl`: boxes a detector left as float32 and labels as int32;
- `big_endian.pkl`: a big-endian int64 array;
- `empty.pkl`: frames with nothing detected.

Usage: python pickles.py OUT_DIR; also writes OUT_DIR/expected.json with the frames as plain lists.
"""

import json
import pickle
import sys
from pathlib import Path

import numpy as np

out = Path(sys.argv[1])
frames_bb = [
    [[101, 52, 121, 73], [10, 200, 60, 239]],
    [[103, 52, 123, 73]],
    [],
    [[0, 0, 319, 239], [5, 6, 7, 8], [30, 40, 50, 60]],
]
frames_labels = [[140, 0], [140], [], [63, 140, 192]]
expected = {}


def write(name, data, protocol=pickle.DEFAULT_PROTOCOL):
    with open(out / name, "wb") as f:
        pickle.dump(data, f, protocol=protocol)


for protocol in (2, 3, 4, 5):
    data = {
        "bb": [np.array(b, dtype=float).reshape(-1, 4).astype(np.int64) for b in frames_bb],
        "labels": [np.array(l, dtype=np.int64) for l in frames_labels],
    }
    write(f"detector_p{protocol}.pkl", data, protocol)
    expected[f"detector_p{protocol}.pkl"] = [frames_bb, frames_labels]

write("perfect.pkl", {"bb": frames_bb, "labels": [np.array(l) for l in frames_labels]})
expected["perfect.pkl"] = [frames_bb, frames_labels]

floats = [[[101.5, 52.25, 121.0, 73.75]], [[0.5, 1.5, 2.5, 3.5]]]
write("float32.pkl", {"bb": [np.array(b, dtype=np.float32) for b in floats],
                      "labels": [np.array([140], dtype=np.int32), np.array([3], dtype=np.int32)]}, 4)
expected["float32.pkl"] = [floats, [[140], [3]]]

write("big_endian.pkl", {"bb": [np.array([[1, 2, 3, 4]], dtype=">i8")], "labels": [np.array([140], dtype=">i8")]}, 4)
expected["big_endian.pkl"] = [[[[1, 2, 3, 4]]], [[140]]]

write("empty.pkl", {"bb": [np.zeros((0, 4), dtype=np.int64) for _ in range(3)],
                    "labels": [np.array([], dtype=np.int64) for _ in range(3)]}, 4)
expected["empty.pkl"] = [[[], [], []], [[], [], []]]

# Bad ones: a label no class has, boxes and labels of different lengths, not a dict.
write("bad_label.pkl", {"bb": [np.array([[1, 2, 3, 4]])], "labels": [np.array([500])]})
write("bad_lengths.pkl", {"bb": [np.array([[1, 2, 3, 4]])], "labels": [np.array([1, 2])]})
write("bad_shape.pkl", [1, 2, 3])
write("bad_box.pkl", {"bb": [np.array([[1, 2, 2e9, 4]])], "labels": [np.array([140])]})
shared = np.array([[1, 2, 3, 4]])
write("bad_shared.pkl", {"bb": [shared, shared], "labels": [np.array([140]), np.array([140])]}, 4)
(out / "not_a_pickle.pkl").write_bytes(b"this is not a pickle")

# A detector's frames with one detection labelled -1 (outside OPNet's class indices): that
# detection is dropped and counted, the others read.
minus_one = [np.array(l, dtype=np.int64) for l in frames_labels]
minus_one[3] = np.array([63, -1, 192], dtype=np.int64)
write("minus_one.pkl", {"bb": [np.array(b, dtype=float).reshape(-1, 4).astype(np.int64) for b in frames_bb],
                        "labels": minus_one}, 4)

# 2,000 nested lists (about 4 KB): refused, not a stack overflow.
sys.setrecursionlimit(10000)
nested = []
for _ in range(2000):
    nested = [nested]
write("nested.pkl", {"bb": nested, "labels": []}, 2)

json.dump(expected, open(out / "expected.json", "w"))
