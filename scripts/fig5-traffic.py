#!/usr/bin/env python3
"""Makes specs/traffic/fig5/car.jsonl: the one car of the DyKnow paper's Fig. 5 experiment
(specs/traffic/fig5.kpl). It drives at 10 m/s on the eastbound lane of the crossing's west arm
(y = -1.75), turns left through the crossing on a 9 m arc and leaves on the northbound lane of the
north arm (x = 1.75): every 0.1 s its centre, heading (radians counter-clockwise from east) and
size, as the rows that the simulated tracker's `traffic_file` reads (docs/simulator.md).

    python3 scripts/fig5-traffic.py > specs/traffic/fig5/car.jsonl

The occluders of specs/traffic/fig5/crossing.json hide it from 3 s to 5 s, 8 s to 10 s and 13 s
to 15 s (the last inside the crossing), so the tracker sees four tracks of about 3 s, each with a
new percept id, like the paper's run.
"""

import json
import math

SPEED = 10.0  # m/s
START_X = -140.0
LANE = 1.75  # lane centre, metres right of the road's centre line
RADIUS = 9.0  # of the left turn
TURN_X = LANE - RADIUS  # x where the turn begins
END_T = 19.0


def position(t):
    """Centre and heading after t seconds."""
    s = SPEED * t
    straight = TURN_X - START_X
    arc = math.pi / 2 * RADIUS
    if s <= straight:
        return START_X + s, -LANE, 0.0
    if s <= straight + arc:
        a = (s - straight) / RADIUS
        return TURN_X + RADIUS * math.sin(a), -LANE + RADIUS * (1 - math.cos(a)), a
    return LANE, -LANE + RADIUS + (s - straight - arc), math.pi / 2


def main():
    for i in range(int(END_T * 10) + 1):
        t = i / 10
        x, y, heading = position(t)
        row = {"time": round(t, 1), "id": "car1", "x": round(x, 3), "y": round(y, 3),
               "heading": round(heading, 4), "length": 4.5, "width": 1.8}
        print(json.dumps(row))


if __name__ == "__main__":
    main()
