"""What kind of vehicle each percept is, from its size and speed (specs/python/vehicle_kind.kpl).

A `python.unit` of KPL (docs/python.md): kpl starts this module in a worker process and calls
the `Classifier` instance with the tracker's percepts of each frame. It keeps, for every percept
id, an exponentially weighted mean of its size and speed (a noisy tracker's single frame says
little), and says:

- `standing`: slower than `min_speed` m/s on average (a false positive on the road, or a stop);
- `truck`: longer than `truck_length` m on average;
- `car`: otherwise.

NumPy does the arithmetic over all percepts of a frame at once.
"""

import numpy as np


class Classifier:
    def __init__(self, truck_length=7.0, min_speed=2.0, smoothing=0.2):
        self.truck_length = truck_length
        self.min_speed = min_speed
        self.smoothing = smoothing
        self.means = {}  # percept id -> [size, speed]

    def __call__(self, percepts):
        if not percepts:
            return []
        ids = [p["id"] for p in percepts]
        sizes = np.array([p["size"] for p in percepts])
        speeds = np.hypot(*np.array([p["vel"] for p in percepts]).T)
        previous = np.array([self.means.get(i, (s, v)) for i, s, v in zip(ids, sizes, speeds)])
        means = previous + self.smoothing * (np.column_stack([sizes, speeds]) - previous)
        kinds = np.where(
            means[:, 1] < self.min_speed, "standing", np.where(means[:, 0] > self.truck_length, "truck", "car")
        )
        self.means = {i: tuple(m) for i, m in zip(ids, means)}
        return [
            {"id": i, "kind": str(k), "size": float(m[0]), "speed": float(m[1])}
            for i, k, m in zip(ids, kinds, means)
        ]
