#!/usr/bin/env python3
"""Makes the SUMO traffic scenarios that ship in specs/traffic/sumo/ (and the network of the load
benchmark), with SUMO from the `eclipse-sumo` Python package (requirements-test.txt installs it
into .venv; no other SUMO is needed).

Each scenario is a folder with the network (net.xml.gz), the recorded traffic as SUMO's floating
car data (fcd.xml.gz: every vehicle's front-bumper position, compass angle, type, speed, lane and
position along the lane,
every 0.5 s) and, where the traffic uses vehicle types of its own, their definitions (vtypes.xml).
Everything is seeded, so the same SUMO release makes the same traffic (only the files' "generated
on" comments differ, and in `reckless` the TraCI port in the floating car data's header);
`--seed` makes other traffic on the same network (a scenario one did not tune on).

The grid, the random network and the highway also get occluders (occluders.json, the tracker's
`occluders_file`): bridges across the main roads, each as wide as a vehicle at the scenario's
typical speed (the median speed of the moving vehicles in the recording) drives in
OCCLUSION_S seconds, so that the tracker loses a vehicle for about that long and gives it a new
percept id when it comes out. They cross roads between junctions: a vertical one between two
columns of junctions near the middle of the network, and (not on the highway) a horizontal one
between two rows. `--occluders-only` writes them anew for scenario folders that exist.

    .venv/bin/python scripts/sumo-scenarios.py                 # every scenario into specs/traffic/sumo
    .venv/bin/python scripts/sumo-scenarios.py --only grid --out /tmp/s --duration 30
    .venv/bin/python scripts/sumo-scenarios.py --only highway --out /tmp/s --seed 5   # other traffic
    .venv/bin/python scripts/sumo-scenarios.py --occluders-only       # occluders.json anew

Scenarios:
  grid      a 4 x 4 grid of 120 m blocks with traffic lights at every crossing and 80 m roads out of
            town at the edge; random trips from edge to edge (queues at red lights).
  random    a random network of about 50 junctions (netgenerate --rand), priority junctions;
            random trips.
  highway   a straight 2 km road, two lanes each way at 120 km/h, with fast cars (up to 36 m/s)
            and slow trucks (up to 22 m/s): the cars overtake the trucks.
  overtake  a straight 1.5 km road, two lanes one way at 90 km/h, with cars at the limit, a few
            speeders (about 34 m/s), slow trucks (17 m/s) and a car that breaks down for 30 s: overtakes,
            speeding and a stopped vehicle, with lane and
            position along the lane in the floating car data (the truth of kpl score situations).
  motorway  overtakes on another road: a straight 2 km road heading north-north-east, three
            lanes one way at 120 km/h, with cars, speeders (about 42 m/s), vans (30 m/s) and
            16.5 m trucks (22.5 m/s).
  wrong_way a straight 1.2 km road, two lanes one way at 90 km/h, with cars and trucks, and two
            wrong-way drivers on the left lane (20 and 15 m/s, from 30 s and 110 s). SUMO keeps
            vehicles to their lanes' direction, so it simulates them on a hidden edge over that
            lane going the other way; the shipped network does not have it (wrong_way's doc).
  tls_grid  a 3 x 3 grid of 150 m blocks, two lanes each way at 50 km/h, traffic lights at every
            crossing; random trips of cars with a wide spread of speed factors (queues side by
            side at red lights, some cars over the limit): issue 24's traffic made elsewhere.
  spider    a spider network (6 arms, 3 circles), one lane each way at 50 km/h; random trips of
            which every second one ends inside the map (the vehicle leaves where its route ends).
  reckless  overtake's road (600 s) with cars, trucks and reckless drivers whose cut-ins after an
            overtake are made with TraCI (CutIns): the reckless drivers' at about 0.2 to 0.7 s
            of headway, the cars' at 1.5 s or more; truth.jsonl: the reckless cut-ins, computed here
            from the floating car data (reckless_truth), which `kpl situations` reads beside the
            traffic file.
  weaving   a straight 3 km road, two lanes one way at 25 m/s (300 s), with SUMO's sublane model
            (lateral resolution 0.8 m): sober cars, trucks and drunk drivers whose lateral
            position wanders across the lane marking and whose speed swings (under TraCI);
            truth.jsonl: weaving, speed swings and the two together (drunk driving), computed
            here from the floating car data's posLat and speed (weaving_truth).
  no_passing a straight 2 km road, two lanes one way at 25 m/s (600 s), with a solid line
            between the lanes on the 600 m before a priority junction where a side road joins:
            cars and trucks keep to their lane there, reckless drivers overtake across the line
            and through the junction; truth.jsonl: the solid-line and junction overtakes, computed
            here from the floating car data and the network (no_passing_truth).
  town400   only a network: a 20 x 20 grid (400 junctions) with traffic lights, for the benchmark
            of reading SUMO networks (crates/kpl-roads/benches/roads.rs).
"""

import argparse
import gzip
import json
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile

FCD_PERIOD_S = 0.5
STEP_LENGTH_S = 0.1
SEED = 42  # of the trips and the simulation (--seed); the networks keep netgenerate's 42
OCCLUSION_S = 2.0


def sumo_home():
    try:
        import sumo  # the eclipse-sumo package
    except ImportError:
        sys.exit("the eclipse-sumo Python package is missing: run scripts/test once, or "
                 "pip install -r requirements-test.txt")
    return sumo.SUMO_HOME


def run(cmd, cwd):
    env = dict(os.environ, SUMO_HOME=sumo_home())
    result = subprocess.run(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if result.returncode != 0:
        sys.exit("failed: %s\n%s" % (" ".join(cmd), result.stdout))


class Sumo:
    def __init__(self, home, work, seed=None):
        self.home = home
        self.work = work
        self.seed = SEED if seed is None else seed

    def write(self, name, text):
        """Writes one input file of the simulation into the work folder."""
        with open(os.path.join(self.work, name), "w") as f:
            f.write(text)

    def tool(self, name):
        return os.path.join(self.home, "bin", name)

    def netgenerate(self, out, *options):
        run([self.tool("netgenerate"), "--seed", "42", "-o", out] + list(options), self.work)

    def netconvert(self, out, *options):
        run([self.tool("netconvert"), "-o", out] + list(options), self.work)

    def random_trips(self, net, routes, duration, period, *options):
        env_tools = os.path.join(self.home, "tools")
        run([sys.executable, os.path.join(env_tools, "randomTrips.py"), "-n", net, "-r", routes,
             "-b", "0", "-e", str(duration), "-p", str(period), "--seed", str(self.seed),
             ] + list(options), self.work)

    def simulate(self, net, routes, fcd, duration, additional=None, lateral_resolution=None, control=None,
                 lane_change_duration=None):
        """Runs SUMO. With `lateral_resolution` (metres) SUMO's sublane model is on: lane changes
        take time (the vehicle moves sideways at most its `maxSpeedLat`), a vehicle's `lane` is
        the one its centre is on, and the floating car data also has `posLat` (the centre's
        offset from the lane's centre line, positive to the left). With `control` SUMO runs
        under TraCI (its Python API, in the eclipse-sumo package's tools) and `control(traci,
        time)` is called after every step, `time` the simulation's time in seconds."""
        attributes = "x,y,angle,type,speed,lane,pos" + (",posLat" if lateral_resolution else "")
        cmd = [self.tool("sumo"), "-n", net, "-r", routes, "--begin", "0", "--end", str(duration),
               "--step-length", str(STEP_LENGTH_S), "--seed", str(self.seed), "--no-step-log", "--no-warnings",
               "--fcd-output", fcd, "--device.fcd.period", str(FCD_PERIOD_S),
               "--fcd-output.attributes", attributes]
        if additional:
            cmd += ["--additional-files", additional]
        if lateral_resolution:
            cmd += ["--lateral-resolution", str(lateral_resolution)]
        if lane_change_duration:
            cmd += ["--lanechange.duration", str(lane_change_duration)]
        if control is None:
            run(cmd, self.work)
            return
        sys.path.append(os.path.join(self.home, "tools"))
        import traci  # shipped in the eclipse-sumo package's tools
        os.environ["SUMO_HOME"] = self.home
        cwd = os.getcwd()
        os.chdir(self.work)
        try:
            traci.start(cmd, stdout=subprocess.DEVNULL)
            for step in range(1, int(round(duration / STEP_LENGTH_S)) + 1):
                traci.simulationStep()
                control(traci, round(step * STEP_LENGTH_S, 3))
            traci.close()
        finally:
            os.chdir(cwd)


def gzip_to(src, dst):
    with open(src, "rb") as f_in, gzip.GzipFile(dst, "wb", mtime=0) as f_out:
        shutil.copyfileobj(f_in, f_out)


def grid(s, duration):
    s.netgenerate("net.net.xml", "--grid", "--grid.number", "4", "--grid.length", "120",
                  "--grid.attach-length", "80", "--default-junction-type", "traffic_light",
                  "--tls.default-type", "static")
    s.random_trips("net.net.xml", "routes.rou.xml", duration, "1.5", "--fringe-factor", "50",
                   "--min-distance", "300")
    s.simulate("net.net.xml", "routes.rou.xml", "fcd.xml", duration)
    return ["net.net.xml", "fcd.xml"], None


def random_net(s, duration):
    s.netgenerate("net.net.xml", "--rand", "--rand.iterations", "60", "--rand.min-distance", "80",
                  "--rand.max-distance", "200", "--rand.grid", "--default-junction-type", "priority")
    s.random_trips("net.net.xml", "routes.rou.xml", duration, "3", "--fringe-factor", "20",
                   "--min-distance", "300")
    s.simulate("net.net.xml", "routes.rou.xml", "fcd.xml", duration)
    return ["net.net.xml", "fcd.xml"], None


VTYPES = """<additional>
    <vType id="car" vClass="passenger" length="4.6" width="1.8" maxSpeed="36" speedFactor="1.1" speedDev="0.1" lcSpeedGain="2"/>
    <vType id="truck" vClass="truck" length="12.0" width="2.5" maxSpeed="22" speedFactor="1.0" speedDev="0.05"/>
</additional>
"""


def highway(s, duration):
    s.write("nodes.nod.xml", '<nodes>\n    <node id="west" x="0" y="0"/>\n    <node id="east" x="2000" y="0"/>\n</nodes>\n')
    s.write("edges.edg.xml", '<edges>\n'
                '    <edge id="eastbound" from="west" to="east" numLanes="2" speed="33.33"/>\n'
                '    <edge id="westbound" from="east" to="west" numLanes="2" speed="33.33"/>\n'
                '</edges>\n')
    s.write("vtypes.xml", VTYPES)
    s.netconvert("net.net.xml", "-n", "nodes.nod.xml", "-e", "edges.edg.xml", "--no-turnarounds")
    flows = []
    for direction in ["eastbound", "westbound"]:
        flows.append('    <flow id="%s_cars" type="car" route="%s" begin="0" end="%d" vehsPerHour="700" '
                     'departLane="random" departSpeed="max"/>' % (direction, direction, duration))
        flows.append('    <flow id="%s_trucks" type="truck" route="%s" begin="0" end="%d" vehsPerHour="150" '
                     'departLane="0" departSpeed="max"/>' % (direction, direction, duration))
    s.write("routes.rou.xml", '<routes>\n    <route id="eastbound" edges="eastbound"/>\n'
                '    <route id="westbound" edges="westbound"/>\n' + "\n".join(flows) + "\n</routes>\n")
    s.simulate("net.net.xml", "routes.rou.xml", "fcd.xml", duration, additional="vtypes.xml")
    return ["net.net.xml", "fcd.xml"], "vtypes.xml"


OVERTAKE_VTYPES = """<additional>
    <vType id="car" vClass="passenger" length="4.6" width="1.8" maxSpeed="40" speedFactor="1.0" speedDev="0.04" lcSpeedGain="2"/>
    <vType id="speeder" vClass="passenger" length="4.6" width="1.8" maxSpeed="40" speedFactor="1.36" speedDev="0.02" lcSpeedGain="4"/>
    <vType id="truck" vClass="truck" length="12.0" width="2.5" maxSpeed="17" speedFactor="1.0" speedDev="0.03"/>
</additional>
"""


def two_lane_road(s, vtypes, length_m=1500):
    """A straight road (1.5 km unless said), two lanes eastbound at 25 m/s, with the scenario's
    vehicle types."""
    s.write("nodes.nod.xml", '<nodes>\n    <node id="west" x="0" y="0"/>\n    <node id="east" x="%d" y="0"/>\n</nodes>\n' % length_m)
    s.write("edges.edg.xml", '<edges>\n'
                '    <edge id="eastbound" from="west" to="east" numLanes="2" speed="25.0"/>\n'
                '</edges>\n')
    s.write("vtypes.xml", vtypes)
    s.netconvert("net.net.xml", "-n", "nodes.nod.xml", "-e", "edges.edg.xml", "--no-turnarounds")


def overtake(s, duration):
    two_lane_road(s, OVERTAKE_VTYPES)
    flows = ['    <flow id="cars" type="car" route="r" begin="0" end="%d" vehsPerHour="500" '
             'departLane="random" departSpeed="max"/>' % duration,
             '    <flow id="speeders" type="speeder" route="r" begin="0" end="%d" vehsPerHour="150" '
             'departLane="random" departSpeed="max"/>' % duration,
             '    <flow id="trucks" type="truck" route="r" begin="0" end="%d" vehsPerHour="150" '
             'departLane="0" departSpeed="max"/>' % duration,
             # A car that breaks down on the right lane for 30 s: a stopped vehicle outside a queue.
             '    <vehicle id="breakdown" type="car" route="r" depart="60" departLane="0" departSpeed="max">'
             '<stop lane="eastbound_0" endPos="900" duration="30"/></vehicle>']
    s.write("routes.rou.xml", '<routes>\n    <route id="r" edges="eastbound"/>\n' + "\n".join(flows) + "\n</routes>\n")
    s.simulate("net.net.xml", "routes.rou.xml", "fcd.xml", duration, additional="vtypes.xml")
    return ["net.net.xml", "fcd.xml"], "vtypes.xml"


MOTORWAY_VTYPES = """<additional>
    <vType id="car" vClass="passenger" length="4.6" width="1.8" maxSpeed="45" speedFactor="1.0" speedDev="0.05" lcSpeedGain="2"/>
    <vType id="speeder" vClass="passenger" length="4.4" width="1.8" maxSpeed="45" speedFactor="1.25" speedDev="0.03" lcSpeedGain="4"/>
    <vType id="van" vClass="delivery" length="6.5" width="2.1" maxSpeed="30" speedFactor="1.0" speedDev="0.05" lcSpeedGain="1"/>
    <vType id="truck" vClass="truck" length="16.5" width="2.55" maxSpeed="22.5" speedFactor="1.0" speedDev="0.03"/>
</additional>
"""


def motorway(s, duration):
    """Overtakes on a wider, faster road than `overtake`'s, with another traffic mix."""
    s.write("nodes.nod.xml", '<nodes>\n    <node id="south" x="0" y="0"/>\n    <node id="north" x="600" y="1900"/>\n</nodes>\n')
    s.write("edges.edg.xml", '<edges>\n'
                '    <edge id="northbound" from="south" to="north" numLanes="3" speed="33.33"/>\n'
                '</edges>\n')
    s.write("vtypes.xml", MOTORWAY_VTYPES)
    s.netconvert("net.net.xml", "-n", "nodes.nod.xml", "-e", "edges.edg.xml", "--no-turnarounds")
    flows = []
    for name, vtype, per_hour, lane in [("cars", "car", 700, "random"), ("speeders", "speeder", 120, "random"),
                                        ("vans", "van", 200, "random"), ("trucks", "truck", 200, "0")]:
        flows.append('    <flow id="%s" type="%s" route="r" begin="0" end="%d" vehsPerHour="%d" '
                     'departLane="%s" departSpeed="max"/>' % (name, vtype, duration, per_hour, lane))
    s.write("routes.rou.xml", '<routes>\n    <route id="r" edges="northbound"/>\n' + "\n".join(flows) + "\n</routes>\n")
    s.simulate("net.net.xml", "routes.rou.xml", "fcd.xml", duration, additional="vtypes.xml")
    return ["net.net.xml", "fcd.xml"], "vtypes.xml"


def wrong_way(s, duration):
    """Wrong-way drivers, which SUMO cannot make on the network they are wrong on: SUMO simulates
    a network with a hidden one-lane edge `ghost` laid over the left lane of `eastbound`, going
    west, and two vehicles drive it; the shipped network (what the tracker, the anchoring and the
    truth see) is `eastbound` alone, on which they drive against the lane. They pass through the
    eastbound traffic (vehicles on different edges do not see each other)."""
    s.write("nodes.nod.xml", '<nodes>\n    <node id="west" x="0" y="0"/>\n    <node id="east" x="1200" y="0"/>\n'
                '    <node id="ghost_east" x="1200" y="-1.6"/>\n    <node id="ghost_west" x="0" y="-1.6"/>\n'
                '</nodes>\n')
    road = '    <edge id="eastbound" from="west" to="east" numLanes="2" speed="25.0"/>\n'
    # The ghost's one lane has its centre on eastbound_1's (y = -1.6).
    ghost = '    <edge id="ghost" from="ghost_east" to="ghost_west" numLanes="1" speed="25.0" spreadType="center"/>\n'
    s.write("edges.edg.xml", "<edges>\n" + road + "</edges>\n")
    s.write("sim.edg.xml", "<edges>\n" + road + ghost + "</edges>\n")
    s.write("vtypes.xml", OVERTAKE_VTYPES)
    # Both networks in the nodes' own coordinates (netconvert would move each to its own origin).
    for net, edges in [("net.net.xml", "edges.edg.xml"), ("sim.net.xml", "sim.edg.xml")]:
        s.netconvert(net, "-n", "nodes.nod.xml", "-e", edges, "--no-turnarounds", "--offset.disable-normalization")
    flows = ['    <flow id="cars" type="car" route="r" begin="0" end="%d" vehsPerHour="600" '
             'departLane="random" departSpeed="max"/>' % duration,
             '    <flow id="trucks" type="truck" route="r" begin="0" end="%d" vehsPerHour="150" '
             'departLane="0" departSpeed="max"/>' % duration,
             '    <vehicle id="ghost.0" type="car" route="g" depart="30" departSpeed="20"/>',
             '    <vehicle id="ghost.1" type="car" route="g" depart="110" departSpeed="15"/>']
    s.write("routes.rou.xml", '<routes>\n    <route id="r" edges="eastbound"/>\n    <route id="g" edges="ghost"/>\n'
                + "\n".join(flows) + "\n</routes>\n")
    s.simulate("sim.net.xml", "routes.rou.xml", "fcd.xml", duration, additional="vtypes.xml")
    return ["net.net.xml", "fcd.xml"], "vtypes.xml"


def town400(s, duration):
    s.netgenerate("net.net.xml", "--grid", "--grid.number", "20", "--grid.length", "100",
                  "--default-junction-type", "traffic_light", "--tls.default-type", "static")
    return ["net.net.xml"], None


def junction_coordinates(net_gz):
    """The x and y coordinates of the network's junctions (not the internal ones) and its
    boundary (x0, y0, x1, y1)."""
    with gzip.open(net_gz, "rt") as f:
        text = f.read()
    bounds = [float(v) for v in re.search(r'convBoundary="([^"]*)"', text).group(1).split(",")]
    xs, ys = set(), set()
    for junction in re.findall(r"<junction [^>]*>", text):
        if 'type="internal"' in junction:
            continue
        xs.add(float(re.search(r' x="([^"]*)"', junction).group(1)))
        ys.add(float(re.search(r' y="([^"]*)"', junction).group(1)))
    return sorted(xs), sorted(ys), bounds


def typical_speed(fcd_gz):
    """The median speed (m/s) of the moving vehicles (over 2 m/s) in a recording."""
    speeds = []
    with gzip.open(fcd_gz, "rt") as f:
        for line in f:
            found = re.search(r' speed="([^"]*)"', line)
            if found and float(found.group(1)) > 2.0:
                speeds.append(float(found.group(1)))
    speeds.sort()
    return speeds[len(speeds) // 2]


def middle_gap(coordinates, low, high):
    """The middle of the gap between two neighbouring coordinates closest to the middle of
    [low, high] (or that middle, with fewer than two coordinates)."""
    centre = (low + high) / 2
    gaps = [(a + b) / 2 for a, b in zip(coordinates, coordinates[1:]) if b - a > 1.0]
    return min(gaps, key=lambda g: abs(g - centre)) if gaps else centre


def occluders(folder, horizontal):
    """Bridges across the main roads of a scenario folder (its net.xml.gz and fcd.xml.gz), each
    OCCLUSION_S seconds wide at the typical speed: a vertical one between two columns of
    junctions near the middle, and with `horizontal` a horizontal one between two rows. They
    reach 30 m beyond the network's boundary."""
    xs, ys, (x0, y0, x1, y1) = junction_coordinates(os.path.join(folder, "net.xml.gz"))
    speed = typical_speed(os.path.join(folder, "fcd.xml.gz"))
    half = speed * OCCLUSION_S / 2
    items = []
    x = middle_gap(xs, x0, x1)
    items.append({"id": "bridge_x%d" % round(x), "kind": "bridge",
                  "polygon": [[round(x - half, 2), y0 - 30], [round(x + half, 2), y0 - 30],
                              [round(x + half, 2), y1 + 30], [round(x - half, 2), y1 + 30]]})
    if horizontal:
        y = middle_gap(ys, y0, y1)
        items.append({"id": "bridge_y%d" % round(y), "kind": "bridge",
                      "polygon": [[x0 - 30, round(y - half, 2)], [x1 + 30, round(y - half, 2)],
                                  [x1 + 30, round(y + half, 2)], [x0 - 30, round(y + half, 2)]]})
    note = ("bridges %.1f m wide: %.1f s at the recording's median speed of moving vehicles, %.1f m/s "
            "(scripts/sumo-scenarios.py)" % (2 * half, OCCLUSION_S, speed))
    with open(os.path.join(folder, "occluders.json"), "w") as f:
        f.write('{"occluders": [\n  %s\n]}\n' % ",\n  ".join(json.dumps(item) for item in items))
    return note

# Cars of the situation scenarios made elsewhere (tls_grid, spider): SUMO's default car with a
# wide spread of speed factors, so that some drive above the limit and some well above it.
TOWN_VTYPES = """<additional>
    <vType id="car" vClass="passenger" length="4.6" width="1.8" maxSpeed="40" speedFactor="normc(1.1,0.15,0.8,1.5)" lcSpeedGain="2"/>
</additional>
"""


def use_vtype(routes, vtype):
    """Gives every vehicle of a routes file the vehicle type `vtype` (defined in vtypes.xml)."""
    with open(routes) as f:
        text = f.read()
    text = re.sub(r'<vehicle id="([^"]*)"', lambda m: '<vehicle id="%s" type="%s"' % (m.group(1), vtype), text)
    with open(routes, "w") as f:
        f.write(text)


def tls_grid(s, duration):
    s.netgenerate("net.net.xml", "--grid", "--grid.number", "3", "--grid.length", "150",
                  "--grid.attach-length", "100", "--default.lanenumber", "2",
                  "--default-junction-type", "traffic_light", "--tls.default-type", "static")
    s.write("vtypes.xml", TOWN_VTYPES)
    s.random_trips("net.net.xml", "routes.rou.xml", duration, "1.2", "--fringe-factor", "50",
                   "--min-distance", "250")
    use_vtype(os.path.join(s.work, "routes.rou.xml"), "car")
    s.simulate("net.net.xml", "routes.rou.xml", "fcd.xml", duration, additional="vtypes.xml")
    return ["net.net.xml", "fcd.xml"], "vtypes.xml"


def end_inside(routes):
    """Cuts the route of every second vehicle to its first half (at least two edges): it ends on
    an edge inside the map, where SUMO removes it at the edge's end (a parking exit, a route
    end)."""
    with open(routes) as f:
        text = f.read()
    count = [0]

    def cut(match):
        count[0] += 1
        edges = match.group(1).split()
        if count[0] % 2 == 0 and len(edges) >= 4:
            edges = edges[:max(2, len(edges) // 2)]
        return '<route edges="%s"' % " ".join(edges)
    text = re.sub(r'<route edges="([^"]*)"', cut, text)
    with open(routes, "w") as f:
        f.write(text)


def spider(s, duration):
    s.netgenerate("net.net.xml", "--spider", "--spider.arm-number", "6", "--spider.circle-number", "3",
                  "--spider.space-radius", "100", "--default.lanenumber", "1", "--default.speed", "13.89",
                  "--no-turnarounds")
    s.write("vtypes.xml", TOWN_VTYPES)
    s.random_trips("net.net.xml", "routes.rou.xml", duration, "4", "--fringe-factor", "100",
                   "--min-distance", "300")
    use_vtype(os.path.join(s.work, "routes.rou.xml"), "car")
    end_inside(os.path.join(s.work, "routes.rou.xml"))
    s.simulate("net.net.xml", "routes.rou.xml", "fcd.xml", duration, additional="vtypes.xml")
    return ["net.net.xml", "fcd.xml"], "vtypes.xml"


RECKLESS_VTYPES = """<additional>
    <vType id="car" vClass="passenger" length="4.6" width="1.8" maxSpeed="40" speedFactor="1.0" speedDev="0.04" lcSpeedGain="2" lcKeepRight="0.3" lcAssertive="1" tau="1.2" minGap="2.5"/>
    <vType id="reckless" vClass="passenger" length="4.6" width="1.8" maxSpeed="40" speedFactor="1.2" speedDev="0.03" lcSpeedGain="1" lcKeepRight="20" lcAssertive="10" lcCooperative="0" tau="0.4" minGap="0.5"/>
    <vType id="truck" vClass="truck" length="12.0" width="2.5" maxSpeed="17" speedFactor="1.0" speedDev="0.03" tau="1.0" minGap="2.5"/>
</additional>
"""
# Lane changes take 1 s (SUMO's default: one step, which the tracker's interpolation between
# samples 0.5 s apart turns into a 6.4 m/s sideways jump that its estimate follows more than a
# second late). The reckless drivers' speed factor is 1.2 (30 m/s; 1.3 before TraCI made their
# cut-ins): 13 m/s faster than a truck, their headway to it grows by 0.38 s from one sample to the
# next, not 0.46 s.
RECKLESS_LANE_CHANGE_S = 1.0


def reckless(s, duration):
    """Overtakes on `overtake`'s road, some of them reckless. Cars and `reckless` drivers
    overtake as SUMO's lane-change model has them (to the left lane for speed), but pull back
    into the right lane only when CutIns (under TraCI) makes them: the reckless drivers in front
    of the vehicle they passed at a headway drawn from RECKLESS_CUT_S, the cars at one drawn
    from SAFE_CUT_S. The truth (reckless_truth, written to truth.jsonl) is computed from the
    floating car data."""
    two_lane_road(s, RECKLESS_VTYPES)
    flows = ['    <flow id="cars" type="car" route="r" begin="0" end="%d" vehsPerHour="350" '
             'departLane="random" departSpeed="max"/>' % duration,
             '    <flow id="reckless" type="reckless" route="r" begin="0" end="%d" vehsPerHour="300" '
             'departLane="random" departSpeed="max"/>' % duration,
             '    <flow id="trucks" type="truck" route="r" begin="0" end="%d" vehsPerHour="250" '
             'departLane="0" departSpeed="max"/>' % duration]
    s.write("routes.rou.xml", '<routes>\n    <route id="r" edges="eastbound"/>\n' + "\n".join(flows) + "\n</routes>\n")
    # Left to SUMO, lane changes took one simulation step and the reckless drivers' headways
    # spread evenly across the 1 s threshold (with `--lanechange.duration 1.5` 1.1 s or more,
    # with the sublane model 0.74 s or more; docs/situations.md#reckless-overtakes): CutIns
    # makes the cut-ins instead.
    s.simulate("net.net.xml", "routes.rou.xml", "fcd.xml", duration, additional="vtypes.xml",
               lane_change_duration=RECKLESS_LANE_CHANGE_S,
               control=CutIns(s.seed, vtype_lengths(os.path.join(s.work, "vtypes.xml"))))
    return ["net.net.xml", "fcd.xml"], "vtypes.xml"


# The cut-ins of the `reckless` scenario, made with TraCI (SUMO's LC2013 lane-change model, not
# the sublane one: under SL2015 the cut-ins TraCI asked for were mostly not made). Lane changes
# take RECKLESS_LANE_CHANGE_S (`--lanechange.duration`): the vehicle moves sideways over that
# time, and SUMO puts it on the new lane (the floating car data's `lane`) half-way, when its
# centre is on the marking, where a camera sees it change lanes. A car or reckless driver on
# the left lane makes no lane changes of its own (lane change mode LEFT_LANE_MODE: it went there
# to overtake, as SUMO's model has it); it pulls back in front of the vehicle `b` it passed (the
# nearest on the right lane behind its back) when the headway it leaves (the gap from b's front
# to its back over b's speed) reaches the one drawn for that pair, RECKLESS_CUT_S for reckless
# drivers (the sample nearest it, within RECKLESS_CUT_MIN_S to RECKLESS_CUT_MAX_S), SAFE_CUT_S
# for cars, and the room in front of it on the right lane is at least CUT_ROOM_S of its speed
# (RECKLESS_ROOM_M for reckless drivers). A reckless driver that missed its window (the room in
# front was short) cuts in as a car would, at a safe headway; one with nobody behind it on the
# right lane pulls in when the room in front is CUT_FREE_ROOM_S of its speed. Changes start so
# that the centre crosses the marking at a floating-car-data sample (every FCD_PERIOD_S): the
# truth sees the headway the change was made at (it grows by the speed difference until the next
# sample otherwise). No cut-in starts beside a vehicle or within CHANGING_NEAR_M of one changing
# lanes, and `b` makes no lane change of its own until CUT_HOLD_S after the cut-in (SUMO's `b`
# would pull out into the cutter's way, not knowing of it). A vehicle back on the right lane
# gets SUMO's default lane change mode again (it may overtake again).
RECKLESS_CUT_S = (0.25, 0.45)
RECKLESS_CUT_MIN_S = 0.2
RECKLESS_CUT_MAX_S = 0.6
SAFE_CUT_S = (1.5, 2.5)
CUT_ROOM_S = 1.0
CUT_FREE_ROOM_S = 4.0
RECKLESS_ROOM_M = 5.0
CUT_RETRY_S = 3.0  # before asking again, if the cut-in was not made
LEFT_LANE_MODE = 0  # only TraCI's changes, made regardless of the others
DEFAULT_LANE_MODE = 0b011001010101  # SUMO's default
HELD_LANE_MODE = 0b000100000000  # no changes of its own
CUT_HOLD_S = 1.0
CHANGING_NEAR_M = 40.0


class CutIns:
    def __init__(self, seed, lengths):
        self.rng = random.Random(seed)
        self.lengths = lengths
        self.targets = {}  # (a, b) -> the headways a cuts in at in front of b
        self.modes = {}
        self.cutting = {}  # vehicle -> the time it was told to cut in
        self.held = {}  # vehicle -> until when it keeps its lane (one cuts in in front of it)

    def __call__(self, traci, time):
        import traci.constants as tc
        for v in traci.simulation.getDepartedIDList():
            traci.vehicle.subscribe(v, [tc.VAR_LANE_INDEX, tc.VAR_LANEPOSITION, tc.VAR_SPEED, tc.VAR_TYPE,
                                         tc.VAR_LANEPOSITION_LAT])
        state = traci.vehicle.getAllSubscriptionResults()
        right = []
        # The vehicles changing lanes now (SUMO moves them sideways over RECKLESS_LANE_CHANGE_S).
        changing = [(v, r[tc.VAR_LANEPOSITION]) for v, r in state.items() if abs(r[tc.VAR_LANEPOSITION_LAT]) > 0.01]
        for v, r in state.items():
            if r[tc.VAR_LANE_INDEX] == 0:
                front = r[tc.VAR_LANEPOSITION]
                right.append((front, front - self.lengths.get(r[tc.VAR_TYPE], 5.0), r[tc.VAR_SPEED], v))
        for a, r in state.items():
            vtype = r[tc.VAR_TYPE]
            lane = r[tc.VAR_LANE_INDEX]
            self.set_mode(traci, a, vtype, lane, time)
            if vtype not in ("car", "reckless"):
                continue
            if lane != 1:
                self.cutting.pop(a, None)
                continue
            if a in self.cutting and time - self.cutting[a] < CUT_RETRY_S:
                continue
            # Where a and the right lane's vehicles will be when a's centre crosses the marking
            # (SUMO moves it to the new lane then): half the lane change after the next step.
            ahead = RECKLESS_LANE_CHANGE_S / 2 - STEP_LENGTH_S
            crossing = (time + ahead) / FCD_PERIOD_S
            if abs(crossing - round(crossing)) > 1e-6:
                continue  # it would cross between two samples
            speed_a = r[tc.VAR_SPEED]
            front_a = r[tc.VAR_LANEPOSITION] + speed_a * ahead
            back_a = front_a - self.lengths.get(vtype, 5.0)
            behind, room, blocked = surroundings(right, front_a, back_a, ahead)
            if blocked or any(abs(pos - r[tc.VAR_LANEPOSITION]) < CHANGING_NEAR_M for v, pos in changing if v != a):
                continue  # beside one, or near one changing lanes (wait until it has)
            if self.cuts_in(a, vtype, speed_a, back_a, behind, room):
                traci.vehicle.changeLane(a, 0, 2 * STEP_LENGTH_S)
                if behind is not None:
                    # b does not pull out into a's way while a cuts in (SUMO would not know).
                    self.held[behind[2]] = time + RECKLESS_LANE_CHANGE_S + CUT_HOLD_S
                self.cutting[a] = time

    def set_mode(self, traci, a, vtype, lane, time):
        """Gives `a` its lane change mode: none of its own while one cuts in in front of it, only
        TraCI's on the left lane (a car or reckless driver), SUMO's default otherwise."""
        if self.held.get(a, -1.0) >= time:
            mode = HELD_LANE_MODE
        elif vtype in ("car", "reckless") and lane == 1:
            mode = LEFT_LANE_MODE
        else:
            mode = DEFAULT_LANE_MODE
        if self.modes.get(a, DEFAULT_LANE_MODE) != mode:
            traci.vehicle.setLaneChangeMode(a, mode)
            self.modes[a] = mode

    def cuts_in(self, a, vtype, speed_a, back_a, behind, room):
        """Whether `a` (on the left lane, `back_a` its back when its centre crosses the marking)
        pulls back in now, in front of `behind` (front, speed, id; None: nobody) with `room`
        metres in front of it."""
        if behind is None:
            return room >= CUT_FREE_ROOM_S * speed_a  # not back behind the one it is to pass
        front_b, speed_b, b = behind
        headway = (back_a - front_b) / max(speed_b, 0.1)
        key = (a, b)
        if key not in self.targets:
            self.targets[key] = (self.rng.uniform(*RECKLESS_CUT_S) if vtype == "reckless" else None,
                                 self.rng.uniform(*SAFE_CUT_S))
        reckless_at, safe_at = self.targets[key]
        # The headway grows by this much from one sample to the next: cut in at the sample nearest
        # the one drawn.
        growth = max(speed_a - speed_b, 0.0) * FCD_PERIOD_S / max(speed_b, 0.1)
        return ((reckless_at is not None and reckless_at - growth / 2 <= headway
                 and RECKLESS_CUT_MIN_S <= headway <= RECKLESS_CUT_MAX_S and room >= RECKLESS_ROOM_M)
                or (headway >= safe_at and room >= CUT_ROOM_S * speed_a))


def surroundings(right, front_a, back_a, ahead):
    """The right lane around a vehicle on the left lane whose front and back will be at `front_a`
    and `back_a` in `ahead` seconds, each right-lane vehicle (front, back, speed, id) moved on as
    far: the nearest one behind its back (front, speed, id; None), the room from its front to the
    back of the nearest one in front (metres), and whether one is beside it."""
    behind = None
    room = float("inf")
    blocked = False
    for front_v, back_v, speed_v, v in right:
        front_v += speed_v * ahead
        back_v += speed_v * ahead
        if front_v < back_a:
            if behind is None or front_v > behind[0]:
                behind = (front_v, speed_v, v)
        elif back_v > front_a:
            room = min(room, back_v - front_a)
        else:
            blocked = True
    return behind, room, blocked


# The truth of the reckless overtake, from SUMO's floating car data alone (not from KPL's
# relations): `a` overtakes `b` recklessly when it changes lane into `b`'s lane in front of `b`
# (both on one edge, b behind: b's front behind a's back) and stays on it for RECKLESS_STAY_S
# (a lane change undone at once is no cut-in a camera could see), having been behind `b` (a's front
# behind b's back) on that edge within RECKLESS_WINDOW_S before, both moving at least
# RECKLESS_MIN_SPEED, and the gap it leaves (a's back to b's front, metres) is less than
# RECKLESS_HEADWAY_S seconds of b's speed: b must brake or drive closer than the one-second
# rule. The situation runs from the last sample a was behind b to the cut-in's sample. Cut-ins
# by vehicles present for less than SETTLE_S are left out (the tracker has not anchored them).
RECKLESS_HEADWAY_S = 1.0
RECKLESS_WINDOW_S = 30.0
RECKLESS_MIN_SPEED = 3.0
RECKLESS_STAY_S = 1.0
SETTLE_S = 3.0


def fcd_samples(fcd_gz):
    """(time, {vehicle: (edge, lane, front pos, speed, type, y)}) of a recording."""
    out = []
    with gzip.open(fcd_gz, "rt") as f:
        text = f.read()
    for block in re.finditer(r'<timestep time="([^"]*)"(.*?)</timestep>', text, re.S):
        vehicles = {}
        for v in re.finditer(r"<vehicle ([^>]*)/>", block.group(2)):
            a = dict(re.findall(r'(\w+)="([^"]*)"', v.group(1)))
            lane = a["lane"]
            vehicles[a["id"]] = (lane.rsplit("_", 1)[0], lane, float(a["pos"]), float(a["speed"]),
                                 a.get("type", ""), float(a["y"]))
        out.append((float(block.group(1)), vehicles))
    return out


def vtype_lengths(vtypes_xml):
    with open(vtypes_xml) as f:
        text = f.read()
    return {m.group(1): float(m.group(2)) for m in re.finditer(r'<vType id="([^"]*)"[^>]*length="([^"]*)"', text)}


def write_truth(folder, lines):
    """Writes the true situations (dicts with `kind`, `objects`, `start`, `end`, ...) to
    truth.jsonl in a scenario folder, one JSON object a line, in the order given."""
    with open(os.path.join(folder, "truth.jsonl"), "w") as f:
        for line in lines:
            f.write(json.dumps(line) + "\n")


def reckless_truth(folder):
    """Writes truth.jsonl in a scenario folder: one line per reckless cut-in (module comment
    above; the safe ones are counted, not written), with `kind` reckless_overtake,
    `objects` [a, b], `start` and `end` in seconds from the recording's first time, `headway_s`,
    and `entering` when a vehicle was present for less than SETTLE_S."""
    samples = fcd_samples(os.path.join(folder, "fcd.xml.gz"))
    lengths = vtype_lengths(os.path.join(folder, "vtypes.xml"))
    origin = samples[0][0] if samples else 0.0
    first_seen = {}
    behind_at = {}  # (a, b) -> last time a's front was behind b's back on one edge
    lines = []
    previous = {}
    # (vehicle, time) -> the last time of the run of samples on its lane from that time.
    stay_end = {}
    following = {}
    for time, vehicles in reversed(samples):
        for v, d in vehicles.items():
            later = following.get(v)
            end = later[1] if later and later[0] == d[1] else time
            following[v] = (d[1], end)
            stay_end[(v, time)] = end
    for time, vehicles in samples:
        for v in vehicles:
            first_seen.setdefault(v, time)
        for a, (edge_a, lane_a, front_a, speed_a, type_a, _) in vehicles.items():
            back_a = front_a - lengths.get(type_a, 5.0)
            for b, (edge_b, lane_b, front_b, speed_b, type_b, _) in vehicles.items():
                if a == b or edge_a != edge_b:
                    continue
                back_b = front_b - lengths.get(type_b, 5.0)
                if front_a < back_b and back_b - front_a < 50.0:
                    behind_at[(a, b)] = time
                was = previous.get(a)
                cut_in = (was is not None and was[0] == edge_a and was[1] != lane_a and lane_b == lane_a
                          and front_b < back_a and stay_end[(a, time)] - time >= RECKLESS_STAY_S)
                if not cut_in:
                    continue
                start = behind_at.get((a, b))
                if start is None or time - start > RECKLESS_WINDOW_S:
                    continue
                del behind_at[(a, b)]  # one cut-in per overtake
                if speed_a < RECKLESS_MIN_SPEED or speed_b < RECKLESS_MIN_SPEED:
                    continue
                gap = back_a - front_b
                headway = gap / speed_b
                entering = min(time - first_seen[a], time - first_seen[b]) < SETTLE_S
                kind = "reckless_overtake" if headway < RECKLESS_HEADWAY_S else "safe_cut_in"
                lines.append({"kind": kind, "objects": [a, b], "start": round(start - origin, 3),
                              "end": round(time - origin, 3), "gap_m": round(gap, 2),
                              "headway_s": round(headway, 3), "entering": entering})
        previous = {v: (d[0], d[1]) for v, d in vehicles.items()}
    with open(os.path.join(folder, "truth.jsonl"), "w") as f:
        for line in lines:
            if line["kind"] == "reckless_overtake":
                f.write(json.dumps(line) + "\n")
    headways = {}
    for line in lines:
        headways.setdefault(line["kind"], []).append(line["headway_s"])
    return "truth.jsonl: %s" % ", ".join("%d %s (headways %.2f-%.2f s)" % (len(h), k, min(h), max(h))
                                         for k, h in sorted(headways.items()))


# Weaving (probable drunk driving): SUMO's sublane model (lateral resolution 0.8 m) with
# `drunk` drivers whose lateral position wanders (SL2015's lcSigma 1.5: they drift across the
# lane marking and back every 5 to 20 s, at up to 2.5 m/s sideways) and whose speed swings
# (SpeedSwings below; SUMO's own sigma 0.9 and speedDev 0.1 only make it jitter by a few tenths
# of a m/s), beside sober cars (lcSigma 0: they keep to their lane's centre and change lanes to
# overtake) and trucks.
WEAVING_VTYPES = """<additional>
    <vType id="car" vClass="passenger" length="4.6" width="1.8" maxSpeed="40" speedFactor="1.0" speedDev="0.05" lcSpeedGain="2" laneChangeModel="SL2015"/>
    <vType id="drunk" vClass="passenger" length="4.6" width="1.8" maxSpeed="40" speedFactor="1.0" speedDev="0.1" sigma="0.9" lcSigma="1.5" maxSpeedLat="2.5" laneChangeModel="SL2015" latAlignment="arbitrary"/>
    <vType id="truck" vClass="truck" length="12.0" width="2.5" maxSpeed="17" speedFactor="1.0" speedDev="0.03" laneChangeModel="SL2015"/>
</additional>
"""
WEAVING_LATERAL_RESOLUTION_M = 0.8
WEAVING_ROAD_M = 3000


def weaving(s, duration):
    """Weaving drivers among sober ones on `overtake`'s road (WEAVING_VTYPES); the truth
    (weaving_truth, written to truth.jsonl) is computed from the floating car data's `posLat`."""
    two_lane_road(s, WEAVING_VTYPES, length_m=WEAVING_ROAD_M)
    flows = ['    <flow id="cars" type="car" route="r" begin="0" end="%d" vehsPerHour="500" '
             'departLane="random" departSpeed="max"/>' % duration,
             '    <flow id="drunk" type="drunk" route="r" begin="0" end="%d" vehsPerHour="90" '
             'departLane="random" departSpeed="max"/>' % duration,
             '    <flow id="trucks" type="truck" route="r" begin="0" end="%d" vehsPerHour="100" '
             'departLane="0" departSpeed="max"/>' % duration]
    s.write("routes.rou.xml", '<routes>\n    <route id="r" edges="eastbound"/>\n' + "\n".join(flows) + "\n</routes>\n")
    s.simulate("net.net.xml", "routes.rou.xml", "fcd.xml", duration, additional="vtypes.xml",
               lateral_resolution=WEAVING_LATERAL_RESOLUTION_M, control=SpeedSwings(s.seed))
    return ["net.net.xml", "fcd.xml"], "vtypes.xml"


# A drunk driver's speed swings: SWING_EVERY_S after it appears, and again that long after each
# swing, it slows down by SWING_DROP_MPS over SWING_FALL_S (TraCI's slowDown) and then drives on
# as SUMO's car-following model lets it, speeding up again at its acceleration (2.6 m/s^2, less
# its dawdling). The cars behind it slow down with it.
SWING_EVERY_S = (5.0, 12.0)
SWING_DROP_MPS = (3.0, 6.0)
SWING_FALL_S = (1.5, 3.0)
SWING_MIN_MPS = 8.0


class SpeedSwings:
    def __init__(self, seed):
        self.rng = random.Random(seed)
        self.next = {}  # drunk driver -> when its next swing starts
        self.falling = {}  # drunk driver -> when its slowing down ends

    def __call__(self, traci, time):
        for v in traci.simulation.getDepartedIDList():
            if traci.vehicle.getTypeID(v) == "drunk":
                self.next[v] = time + self.rng.uniform(*SWING_EVERY_S)
        for v in traci.simulation.getArrivedIDList():
            self.next.pop(v, None)
            self.falling.pop(v, None)
        for v, until in list(self.falling.items()):
            if time >= until:
                traci.vehicle.setSpeed(v, -1)  # back to SUMO's car following
                del self.falling[v]
        for v, at in self.next.items():
            if time >= at and v not in self.falling:
                fall = self.rng.uniform(*SWING_FALL_S)
                target = max(traci.vehicle.getSpeed(v) - self.rng.uniform(*SWING_DROP_MPS), SWING_MIN_MPS)
                traci.vehicle.slowDown(v, target, fall)
                self.falling[v] = time + fall
                self.next[v] = time + fall + self.rng.uniform(*SWING_EVERY_S)


# The truth of weaving, from SUMO's floating car data alone (`posLat`: the centre's offset from
# its lane's centre line; not from KPL's relations): a vehicle *departs* its lane when its centre
# comes more than WEAVE_OUT_M from the lane's centre line (on a 3.2 m lane, a 1.8 m wide car is
# then 0.3 m over the marking; a lane change is a departure too: SUMO switches `lane` as the
# centre crosses the marking, 1.6 m from the lane's centre, which counts even when neither
# sample on either side of the switch, 0.5 s apart, is over WEAVE_OUT_M) and
# *returns* when its centre is again within WEAVE_IN_M of a lane's centre line. It weaves when
# WEAVE_COUNT departures and returns follow one another within WEAVE_WINDOW_S (the first
# departure to the last return); a sober overtake is two (out and back). Overlapping weaving
# windows of one vehicle are one situation, from its first departure to its last return.
# Samples within SETTLE_S of a vehicle's appearance are left out (the tracker has not anchored it).
WEAVE_OUT_M = 1.3
WEAVE_IN_M = 0.5
WEAVE_COUNT = 3
WEAVE_WINDOW_S = 30.0
# Speed swings, from the floating car data's `speed` alone: a vehicle's speed falls by at least
# SWING_MPS from its highest speed of the SWING_LEG_S before the lowest one (and since the last
# swing) and rises again by SWING_MPS from the lowest speed within SWING_LEG_S. The swing lasts from
# when the fall reached SWING_MPS to when the rise did (so a plateau's length or jitter does not
# move it). It swings when SWING_COUNT swings follow one another within SWING_WINDOW_S (first
# fall to last rise); overlapping windows are one situation. A car behind a drunk driver swings
# with it; a car that slows down behind a truck and speeds up to overtake it swings once.
SWING_MPS = 2.0
SWING_LEG_S = 8.0
SWING_COUNT = 2
SWING_WINDOW_S = 30.0
# Probable drunk driving: a vehicle's weaving while its speed swings (a speed-swing situation at
# most DRUNK_WITHIN_S before or after it); the situation is the weaving's.
DRUNK_WITHIN_S = 30.0


def episodes_of(events, count, window):
    """[start, end, n] windows of `count` consecutive (start, end) events within `window`
    seconds (first start to last end), overlapping windows merged (n: events in it)."""
    episodes = []
    for i in range(len(events) - count + 1):
        start, end = events[i][0], events[i + count - 1][1]
        if end - start > window:
            continue
        if episodes and start <= episodes[-1][1]:
            episodes[-1][1] = end
            episodes[-1][2] += 1
        else:
            episodes.append([start, end, count])
    return episodes


def speed_swings(samples):
    """The (fallen, risen) times of a vehicle's speed swings in [(time, speed)] (comment above).
    Both legs are measured where they happened, not from a plateau's first or last sample: the
    fall from the highest speed of the SWING_LEG_S before the lowest one, the rise from the last
    sample at the lowest speed; a swing lasts from when the fall reached SWING_MPS to when the
    rise did, as a chronicle's fall and rise events would time it.

    A plateau at 30 m/s whose highest sample (30.1) is 11 s before a fall to 25 m/s over 2 s:
    one swing, from 1 s into the fall (28 m/s) to the rise back to 27 m/s.

    >>> plateau = [(t * 0.5, 30.1 if t == 0 else 30.0) for t in range(23)]
    >>> fall = [(11.5, 29.0), (12.0, 28.0), (12.5, 27.0), (13.0, 25.0), (13.5, 25.0)]
    >>> speed_swings(plateau + fall + [(14.0, 26.0), (14.5, 27.0), (15.0, 29.0)])
    [(12.0, 14.5)]

    A fall by 2 m/s that takes 10 s, or a rise that does, is not a swing.

    >>> slow = [(t * 0.5, 30.0 - 0.1 * t) for t in range(21)] + [(10.5, 28.0), (11.0, 29.0)]
    >>> speed_swings(slow)
    []
    >>> speed_swings([(0.0, 30.0), (1.0, 27.0), (2.0, 28.0), (6.0, 28.5), (10.0, 29.0)])
    []
    """
    swings = []
    since = 0  # no peak before this sample: the last swing's end
    fallen = None  # the time the speed had fallen by SWING_MPS
    trough = lowest = None  # the lowest (time, speed) since then, and its index

    def peak_before(i):
        """The highest speed of samples[since..=i] within SWING_LEG_S before samples[i] (walks back
        over those SWING_LEG_S only, not over everything since the last swing)."""
        j, peak = i, samples[i][1]
        while j > since and samples[j - 1][0] >= samples[i][0] - SWING_LEG_S:
            j -= 1
            peak = max(peak, samples[j][1])
        return peak

    for i, (time, speed) in enumerate(samples):
        if fallen is None:
            if peak_before(i) - speed >= SWING_MPS:
                fallen, trough, lowest = time, (time, speed), i
        elif speed <= trough[1]:
            trough, lowest = (time, speed), i
        elif speed - trough[1] >= SWING_MPS:
            if peak_before(lowest) - trough[1] >= SWING_MPS and time - trough[0] <= SWING_LEG_S:
                swings.append((fallen, time))
            since, fallen = i, None
    return swings


def weaving_truth(folder):
    """Writes truth.jsonl in a scenario folder: one line per situation (comments above), `kind`
    weaving (`departures`: how many in it), speed_swings (`swings`) or drunk_driving, `objects`
    [vehicle], `start` and `end` in seconds from the recording's first time."""
    with gzip.open(os.path.join(folder, "fcd.xml.gz"), "rt") as f:
        text = f.read()
    origin = None
    series = {}  # vehicle -> [(time, |posLat|)]
    for block in re.finditer(r'<timestep time="([^"]*)"(.*?)</timestep>', text, re.S):
        time = float(block.group(1))
        origin = time if origin is None else origin
        for v in re.finditer(r"<vehicle ([^>]*)/>", block.group(2)):
            a = dict(re.findall(r'(\w+)="([^"]*)"', v.group(1)))
            # Without SUMO's sublane model there is no posLat: departures are the lane switches.
            lateral = abs(float(a.get("posLat", 0.0)))
            series.setdefault(a["id"], []).append((time, lateral, a["lane"], float(a["speed"])))
    lines = []
    for vehicle, samples in series.items():
        first = samples[0][0]
        departures = []  # (departure, return)
        out = None
        lane = None
        for time, offset, now_on, _ in samples:
            crossed = lane is not None and now_on != lane  # the centre crossed a marking
            lane = now_on
            if time - first < SETTLE_S:
                continue
            if out is None and (offset > WEAVE_OUT_M or crossed):
                out = time
            elif out is not None and offset < WEAVE_IN_M:
                departures.append((out, time))
                out = None
        weaving = episodes_of(departures, WEAVE_COUNT, WEAVE_WINDOW_S)
        speed = speed_swings([(t, v) for t, _, _, v in samples if t - first >= SETTLE_S])
        swinging = episodes_of(speed, SWING_COUNT, SWING_WINDOW_S)
        drunk = [w for w in weaving
                 if any(sw[0] <= w[1] + DRUNK_WITHIN_S and w[0] - DRUNK_WITHIN_S <= sw[1] for sw in swinging)]
        for kind, found, extra in [("weaving", weaving, "departures"), ("speed_swings", swinging, "swings"),
                                   ("drunk_driving", drunk, "departures")]:
            for episode in found:
                lines.append({"kind": kind, "objects": [vehicle], "start": round(episode[0] - origin, 3),
                              "end": round(episode[1] - origin, 3), extra: episode[2]})
    lines.sort(key=lambda line: (line["start"], line["objects"], line["kind"]))
    write_truth(folder, lines)
    counts = {}
    for line in lines:
        counts.setdefault(line["kind"], set()).add(line["objects"][0])
    return "truth.jsonl: " + ", ".join("%d %s (%d vehicles)" % (sum(1 for l in lines if l["kind"] == k), k, len(v))
                                       for k, v in sorted(counts.items()))


# The scenarios whose truth is computed here (truth.jsonl), not by kpl situations.
# No passing: a straight 2 km road, two lanes one way at 25 m/s, in three edges: `approach`
# (700 m), `no_passing` (600 m: a solid line between the lanes, SUMO's changeLeft/changeRight
# allowing only emergency vehicles to cross it) up to a priority junction `j` where a side road
# from the south joins, and `exit` (700 m) after it. Sober cars and trucks keep to their lane on
# `no_passing` (a car that pulled out before it passes there on the left lane and stays on it
# until `exit`); `reckless` drivers overtake wherever SUMO's lane-change model has them, across
# the solid line and through the junction. SUMO itself honours the line, for its drivers and for
# TraCI's lane changes alike, so the traffic is simulated on a copy of the network without it
# (NoPassing keeps the sober drivers to their lane there); the shipped network has it, and the
# two are the same but for the lanes' changeLeft/changeRight (checked).
NO_PASSING_VTYPES = """<additional>
    <vType id="car" vClass="passenger" length="4.6" width="1.8" maxSpeed="40" speedFactor="1.0" speedDev="0.06" lcSpeedGain="2" tau="1.2"/>
    <vType id="reckless" vClass="passenger" length="4.6" width="1.8" maxSpeed="40" speedFactor="1.25" speedDev="0.04" lcSpeedGain="10" lcKeepRight="5" lcAssertive="5" tau="0.6" minGap="1.0"/>
    <vType id="truck" vClass="truck" length="12.0" width="2.5" maxSpeed="17" speedFactor="1.0" speedDev="0.03"/>
</additional>
"""
NO_PASSING_EDGES = """<edges>
    <edge id="approach" from="west" to="zone" numLanes="2" speed="25.0" priority="3"/>
    <edge id="no_passing" from="zone" to="j" numLanes="2" speed="25.0" priority="3">%s
    </edge>
    <edge id="exit" from="j" to="east" numLanes="2" speed="25.0" priority="3"/>
    <edge id="side" from="south" to="j" numLanes="1" speed="13.9" priority="1"/>
</edges>
"""
SOLID_LINE = """
        <lane index="0" changeLeft="emergency authority"/>
        <lane index="1" changeRight="emergency authority"/>"""
NO_PASSING_LANE_CHANGE_S = 1.0


def no_passing(s, duration):
    """Overtakes across a solid line and through a junction (module comment above)."""
    s.write("nodes.nod.xml", '<nodes>\n    <node id="west" x="0" y="0"/>\n    <node id="zone" x="700" y="0"/>\n'
            '    <node id="j" x="1300" y="0" type="priority"/>\n    <node id="east" x="2000" y="0"/>\n'
            '    <node id="south" x="1300" y="-400"/>\n</nodes>\n')
    s.write("vtypes.xml", NO_PASSING_VTYPES)
    s.write("marked.edg.xml", NO_PASSING_EDGES % SOLID_LINE)
    s.write("unmarked.edg.xml", NO_PASSING_EDGES % "")
    for edges, net in (("marked.edg.xml", "net.net.xml"), ("unmarked.edg.xml", "unmarked.net.xml")):
        s.netconvert(net, "-n", "nodes.nod.xml", "-e", edges, "--no-turnarounds")
    unmark = lambda text: re.sub(r' change(Left|Right)="[^"]*"', "", re.sub(r"<!--.*?-->", "", text, flags=re.S))
    with open(os.path.join(s.work, "net.net.xml")) as a, open(os.path.join(s.work, "unmarked.net.xml")) as b:
        marked, unmarked = a.read(), b.read()
    assert marked != unmarked and unmark(marked) == unmark(unmarked), "the networks differ beyond the solid line"
    flows = ['    <flow id="cars" type="car" route="main" begin="0" end="%d" vehsPerHour="300" '
             'departLane="random" departSpeed="max"/>' % duration,
             '    <flow id="reckless" type="reckless" route="main" begin="0" end="%d" vehsPerHour="300" '
             'departLane="random" departSpeed="max"/>' % duration,
             '    <flow id="trucks" type="truck" route="main" begin="0" end="%d" vehsPerHour="500" '
             'departLane="0" departSpeed="max"/>' % duration,
             '    <flow id="side" type="car" route="side" begin="0" end="%d" vehsPerHour="120" '
             'departSpeed="max"/>' % duration]
    s.write("routes.rou.xml", '<routes>\n    <route id="main" edges="approach no_passing exit"/>\n'
            '    <route id="side" edges="side exit"/>\n' + "\n".join(flows) + "\n</routes>\n")
    s.simulate("unmarked.net.xml", "routes.rou.xml", "fcd.xml", duration, additional="vtypes.xml",
               lane_change_duration=NO_PASSING_LANE_CHANGE_S, control=NoPassing())
    return ["net.net.xml", "fcd.xml"], "vtypes.xml"


class NoPassing:
    """Keeps every vehicle but the reckless drivers to its lane on `no_passing` (lane change mode
    HELD_LANE_MODE there, SUMO's default elsewhere)."""

    def __init__(self):
        self.held = set()

    def __call__(self, traci, time):
        import traci.constants as tc
        for v in traci.simulation.getDepartedIDList():
            traci.vehicle.subscribe(v, [tc.VAR_ROAD_ID, tc.VAR_TYPE])
        for v, r in traci.vehicle.getAllSubscriptionResults().items():
            hold = r[tc.VAR_ROAD_ID] == "no_passing" and r[tc.VAR_TYPE] != "reckless"
            if hold != (v in self.held):
                traci.vehicle.setLaneChangeMode(v, HELD_LANE_MODE if hold else DEFAULT_LANE_MODE)
                (self.held.add if hold else self.held.discard)(v)


# The truth of the no-passing scenario, from SUMO's floating car data and the shipped network
# alone (not from KPL's relations). `a` passes `b` when a's front goes from behind b's back (the
# last such sample: `start`) to a's back in front of b's front (the first such sample after it:
# `end`) within PASS_WINDOW_S, both on the main road (not the side road) all along, b moving at
# RECKLESS_MIN_SPEED or more at the end. The road runs along x, so "in front" compares the
# front bumpers' x (the floating car data's position) less the vehicles' lengths. A pass is a
# `solid_line_overtake` when a changes lanes across a solid line (from lane L of an edge to
# another lane of it, L's changeLeft or changeRight in the network not allowing passenger cars
# that way) from SOLID_BEFORE_S before `start` to SOLID_AFTER_S after `end` (the pull-out or the
# cut-in of that overtake), and a `junction_overtake` when a crosses the junction alongside b:
# the pass overlaps a's crossing. Samples are 0.5 s apart and a car crosses the 11 m junction in
# about 0.4 s, often between two, so these times are interpolated linearly between samples: the
# pass from the instant a's front reaches b's back to the instant a's back clears b's front, the
# crossing from the instant a's centre (its front less half its length) passes the end of the
# `no_passing` lanes to the instant it passes the start of the `exit` lanes (x of the lanes'
# shapes in the network). Passes by vehicles present for less than SETTLE_S are `entering`.
PASS_WINDOW_S = 30.0
SOLID_BEFORE_S = 10.0
SOLID_AFTER_S = 10.0


def solid_lines(net_gz):
    """{(lane id, +1 left / -1 right)} of the lane changes the network forbids passenger cars."""
    with gzip.open(net_gz, "rt") as f:
        text = f.read()
    forbidden = set()
    for attributes in re.findall(r"<lane ([^>]*)>", text):
        a = dict(re.findall(r'(\w+)="([^"]*)"', attributes))
        for name, side in (("changeLeft", 1), ("changeRight", -1)):
            if name in a and not ({"passenger", "all"} & set(a[name].split())):
                forbidden.add((a["id"], side))
    return forbidden


def junction_span(net_gz):
    """The x where the `no_passing` lanes end and the `exit` lanes begin (the junction between)."""
    with gzip.open(net_gz, "rt") as f:
        text = f.read()
    shapes = dict(re.findall(r'<lane id="([^"]*)"[^>]*shape="([^"]*)"', text))
    x = lambda lane, point: float(shapes[lane].split()[point].split(",")[0])
    return max(x("no_passing_0", -1), x("no_passing_1", -1)), min(x("exit_0", 0), x("exit_1", 0))


def crossing_time(t0, f0, t1, f1):
    """When a quantity that was f0 at t0 and f1 at t1 (f0 < 0 <= f1) reached 0, linearly."""
    return t0 + (t1 - t0) * (-f0) / (f1 - f0)


def no_passing_truth(folder):
    """Writes truth.jsonl in a scenario folder: the solid-line and junction overtakes (the comment
    above), each with `kind`, `objects` [a, b], `start`, `end` (seconds from the recording's first
    time) and `entering`."""
    forbidden = solid_lines(os.path.join(folder, "net.xml.gz"))
    x_in, x_out = junction_span(os.path.join(folder, "net.xml.gz"))
    lengths = vtype_lengths(os.path.join(folder, "vtypes.xml"))
    samples = []  # (time, {vehicle: (x, edge, lane, speed, length)})
    with gzip.open(os.path.join(folder, "fcd.xml.gz"), "rt") as f:
        text = f.read()
    for block in re.finditer(r'<timestep time="([^"]*)"(.*?)</timestep>', text, re.S):
        vehicles = {}
        for v in re.finditer(r"<vehicle ([^>]*)/>", block.group(2)):
            a = dict(re.findall(r'(\w+)="([^"]*)"', v.group(1)))
            vehicles[a["id"]] = (float(a["x"]), a["lane"].rsplit("_", 1)[0], a["lane"], float(a["speed"]),
                                 lengths.get(a.get("type", ""), 5.0))
        samples.append((float(block.group(1)), vehicles))
    origin = samples[0][0] if samples else 0.0
    first_seen, crossings, junction_at, exit_at = {}, {}, {}, {}
    previous = {}
    for time, vehicles in samples:
        for v, (x, edge, lane, _, length) in vehicles.items():
            first_seen.setdefault(v, time)
            was = previous.get(v)
            if was and was[0] == edge and was[1] != lane:
                side = 1 if int(lane.rsplit("_", 1)[1]) > int(was[1].rsplit("_", 1)[1]) else -1
                if (was[1], side) in forbidden:
                    crossings.setdefault(v, []).append(time)
            centre = x - length / 2
            if was and was[2] < x_in <= centre and was[0] != "side":
                junction_at[v] = crossing_time(was[3], was[2] - x_in, time, centre - x_in)
            if was and was[2] < x_out <= centre and was[0] != "side":
                exit_at[v] = crossing_time(was[3], was[2] - x_out, time, centre - x_out)
        previous = {v: (d[1], d[2], d[0] - d[4] / 2, time) for v, d in vehicles.items()}
    at = {time: vehicles for time, vehicles in samples}
    following = {samples[i][0]: samples[i + 1][0] for i in range(len(samples) - 1)}
    preceding = {later: earlier for earlier, later in following.items()}
    main = lambda d: d[1] != "side" and not d[1].startswith(":j_0")
    behind_at = {}  # (a, b) -> the last time a's front was behind b's back
    lines = []
    for time, vehicles in samples:
        for a, da in vehicles.items():
            for b, db in vehicles.items():
                if a == b:
                    continue
                key = (a, b)
                if not (main(da) and main(db)):
                    behind_at.pop(key, None)
                    continue
                if da[0] < db[0] - db[4]:
                    behind_at[key] = time
                elif da[0] - da[4] > db[0] and key in behind_at:
                    start = behind_at.pop(key)
                    if time - start > PASS_WINDOW_S or db[3] < RECKLESS_MIN_SPEED:
                        continue
                    entering = min(start - first_seen[a], start - first_seen[b]) < SETTLE_S
                    crossed = [t for t in crossings.get(a, []) if start - SOLID_BEFORE_S <= t <= time + SOLID_AFTER_S]
                    if crossed:
                        lines.append({"kind": "solid_line_overtake", "objects": [a, b],
                                      "start": round(min(start, crossed[0]) - origin, 3),
                                      "end": round(max(time, crossed[-1]) - origin, 3), "entering": entering})
                    # The pass's interpolated ends: a's front at b's back, a's back at b's front.
                    gap = lambda t: at[t][a][0] - (at[t][b][0] - at[t][b][4])
                    clear = lambda t: at[t][a][0] - at[t][a][4] - at[t][b][0]
                    begins = crossing_time(start, gap(start), following[start], gap(following[start]))
                    ends = crossing_time(preceding[time], clear(preceding[time]), time, clear(time))
                    if begins <= exit_at.get(a, -1.0) and junction_at.get(a, float("inf")) <= ends:
                        lines.append({"kind": "junction_overtake", "objects": [a, b],
                                      "start": round(start - origin, 3), "end": round(time - origin, 3),
                                      "entering": entering})
    lines.sort(key=lambda line: (line["end"], line["kind"], line["objects"]))
    write_truth(folder, lines)
    counts = {}
    for line in lines:
        counts[line["kind"]] = counts.get(line["kind"], 0) + 1
    return "truth.jsonl: %s; %d solid-line crossings" % (
        ", ".join("%d %s" % (n, k) for k, n in sorted(counts.items())), sum(map(len, crossings.values())))


TRUTHS = {"reckless": reckless_truth, "weaving": weaving_truth, "no_passing": no_passing_truth}

# The scenarios with occluders (and whether they get a horizontal bridge too).
OCCLUDED = {"grid": True, "random": True, "highway": False}


SCENARIOS = {"grid": grid, "random": random_net, "highway": highway, "overtake": overtake,
             "motorway": motorway, "wrong_way": wrong_way, "town400": town400,
             "tls_grid": tls_grid, "spider": spider, "reckless": reckless,
             "weaving": weaving, "no_passing": no_passing}
DURATION_S = {"grid": 300, "random": 300, "highway": 240, "overtake": 240, "motorway": 240,
              "wrong_way": 180, "town400": 0, "tls_grid": 240, "spider": 240, "reckless": 600,
              "weaving": 300, "no_passing": 600}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
    parser.add_argument("--out", default=os.path.join(root, "specs", "traffic", "sumo"),
                        help="folder to write the scenario folders into (default specs/traffic/sumo)")
    parser.add_argument("--only", choices=sorted(SCENARIOS), action="append",
                        help="make only this scenario (may be given more than once)")
    parser.add_argument("--duration", type=int, help="seconds of traffic (default per scenario)")
    parser.add_argument("--seed", type=int, default=SEED,
                        help="seed of the trips and the simulation (default %d: the shipped traffic)" % SEED)
    parser.add_argument("--occluders-only", action="store_true",
                        help="only write occluders.json anew in the scenario folders that exist")
    args = parser.parse_args()
    if args.occluders_only:
        for name in args.only or list(OCCLUDED):
            if name in OCCLUDED:
                print("%s: %s" % (name, occluders(os.path.join(args.out, name), OCCLUDED[name])))
        return
    home = sumo_home()
    for name in args.only or list(SCENARIOS):
        with tempfile.TemporaryDirectory() as work:
            s = Sumo(home, work, args.seed)
            duration = args.duration or DURATION_S[name]
            files, vtypes = SCENARIOS[name](s, duration)
            target = os.path.join(args.out, name)
            os.makedirs(target, exist_ok=True)
            for produced in files:
                stem = produced.split(".")[0]
                gzip_to(os.path.join(work, produced), os.path.join(target, stem + ".xml.gz"))
            if vtypes:
                shutil.copy(os.path.join(work, vtypes), os.path.join(target, "vtypes.xml"))
            if name in OCCLUDED:
                occluders(target, OCCLUDED[name])
            if name in TRUTHS:
                print("%s: %s" % (name, TRUTHS[name](target)))
            sizes = ", ".join("%s %d KiB" % (f, os.path.getsize(os.path.join(target, f)) // 1024)
                              for f in sorted(os.listdir(target)))
            print("%s: %s" % (target, sizes))


if __name__ == "__main__":
    main()
