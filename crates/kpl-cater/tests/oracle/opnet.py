"""An independent re-implementation of OPNet's evaluation (Shamsian et al., "Learning Object
Permanence from Video"), written from reading its code, for kpl-cater's differential test.

Given a data directory in LA-CATER's layout (scenes/<video>.json, scenes/<video>_bb.json,
perception/<video>_<mode>.json) it computes, as OPNet's scripts do:

- the frame annotations: containment (gen_video_labels.py, snitch_containment), containment with
  movement (snitch_containment_with_move) and snitch visibility > 0
  (get_perfect_perception_and_visible_snitch_ratio.py), from the scene JSON and the boxes;
- the programmed heuristic's predictions (HeuristicReasoner + track_and_predict) over a perception;
- the analysis (ResultsAnalyzer + analyze_iou_offline.py): per video the mean IoU over all frames
  and over the frames of each category, from a directory of prediction files.

It also makes OPNet's perfect perception pickles (its `visible_only` mode, with OPNet's class
indices) from a directory in LA-CATER's layout, or the same with occlusion by the union of the
nearer objects' boxes (hard scenes):

    python opnet.py perfect-pickles DATA OUT_DIR opnet|union

Usage: python opnet.py DATA PERCEPTION PREDICTIONS_DIR OUT.json
Writes {"annotations": {video: {"contained", "carried", "visible"}},
        "heuristic": {video: [[x1, y1, x2, y2], ...]},
        "analysis": {video: {"overall", "visible", "occluded", "contained", "carried"}}}
(nan written as null).
"""

import json
import math
import sys
from pathlib import Path

import numpy as np

SNITCH = "Spl_0"
SNITCH_CLASS = "small_gold_spl_metal"
LAST = 299
CAMERA = np.array([7.1146, -6.1746, 5.5963])


def obj_class(o):
    return "_".join(o[k] for k in ("size", "color", "shape", "material"))


def cone_contains(movements, open_end, only=None):
    """(cone, contained, first frame, last frame) for every _contain by a cone."""
    out = []
    for name, actions in movements.items():
        if "Cone" not in name:
            continue
        for i, a in enumerate(actions):
            if "_contain" not in a[0]:
                continue
            if only is not None and a[1] != only:
                continue
            later = [b for b in actions[i:] if "_pick_place" in b[0]]
            end = later[0][2] if later else open_end
            out.append((name, a[1], a[3], end, i))
    return out


def contained(scene):
    frames = set()
    for _, _, start, end, _ in cone_contains(scene["movements"], LAST, SNITCH):
        frames.update(range(start, end + 1))
    return sorted(frames)


def carried(scene):
    frames = set()
    for cone, _, _, end, i in cone_contains(scene["movements"], LAST, SNITCH):
        for b in scene["movements"][cone][i:]:
            if "_slide" in b[0] and b[3] <= end:
                frames.update(range(b[2], b[3] + 1))
    return sorted(frames)


def covered(a, b, da, db, threshold):
    a = [a[0], a[1], a[0] + a[2], a[1] + a[3]]
    b = [b[0], b[1], b[0] + b[2], b[1] + b[3]]
    inter = max(0, min(a[2], b[2]) - max(a[0], b[0]) + 1) * max(0, min(a[3], b[3]) - max(a[1], b[1]) + 1)
    area_a = (a[2] - a[0] + 1) * (a[3] - a[1] + 1)
    area_b = (b[2] - b[0] + 1) * (b[3] - b[1] + 1)
    return inter / min(area_a, area_b) >= threshold and area_a < area_b and da > db


def visible(scene, boxes, frames, ratio=0.0):
    hidden = {}
    classes = {o["instance"]: obj_class(o) for o in scene["objects"]}
    for _, other, start, end, _ in cone_contains(scene["movements"], 300):
        hidden.setdefault(classes[other], []).append((start, end))
    out = []
    for f in range(frames):
        present = []
        for o in scene["objects"]:
            c = obj_class(o)
            if any(s <= f <= e for s, e in hidden.get(c, [])):
                continue
            loc = np.array(o["locations"][str(f)])
            present.append((c, boxes[c + "_" + o["instance"]][f], np.linalg.norm(CAMERA - loc)))
        snitch = [p for p in present if p[0] == SNITCH_CLASS]
        if not snitch:
            continue
        s = snitch[0]
        others = [p for p in present if p is not s]
        if not any(covered(s[1], p[1], s[2], p[2], 1.0 - ratio) for p in others):
            out.append(f)
    return out


def opnet_class_indices():
    """OPNet's object_indices.py table, by its rule: sizes large, medium, small; materials metal,
    rubber; within each, color_shape sorted, the snitch (gold spl) among the small metal ones."""
    colors = ["blue", "brown", "cyan", "gray", "green", "purple", "red", "yellow"]
    shapes = ["cone", "cube", "cylinder", "sphere"]
    table = []
    for size in ["large", "medium", "small"]:
        for material in ["metal", "rubber"]:
            group = sorted([(c, s) for c in colors for s in shapes]
                           + ([("gold", "spl")] if (size, material) == ("small", "metal") else []))
            table += [f"{size}_{c}_{s}_{material}" for c, s in group]
    return {name: i for i, name in enumerate(table)}


def perfect_perception(scene, boxes, frames, ratio=0.0, camera=None):
    """get_perfect_perception_and_visible_snitch_ratio.py, visible_only: every object not contained
    (by class) and not occluded. With `camera`, an object is occluded when the boxes of the nearer
    objects cover all its pixels together (rasterized here), distances from that camera."""
    indices = opnet_class_indices()
    hidden = {}
    classes = {o["instance"]: obj_class(o) for o in scene["objects"]}
    for _, other, start, end, _ in cone_contains(scene["movements"], 300):
        hidden.setdefault(indices[classes[other]], []).append((start, end))
    out_bb, out_labels = [], []
    for f in range(frames):
        shown = []
        for o in scene["objects"]:
            label = indices[obj_class(o)]
            if any(s <= f <= e for s, e in hidden.get(label, [])):
                continue
            x, y, w, h = boxes[obj_class(o) + "_" + o["instance"]][f]
            loc = np.array(o["locations"][str(f)])
            shown.append((label, [x, y, x + w, y + h], loc))
        occluded = [False] * len(shown)
        if camera is None:
            dist = [np.linalg.norm(CAMERA - s[2]) for s in shown]
            for i in range(len(shown)):
                for j in range(i, len(shown)):
                    a, b = shown[i][1], shown[j][1]
                    inter = max(0, min(a[2], b[2]) - max(a[0], b[0]) + 1) * max(0, min(a[3], b[3]) - max(a[1], b[1]) + 1)
                    area_a = (a[2] - a[0] + 1) * (a[3] - a[1] + 1)
                    area_b = (b[2] - b[0] + 1) * (b[3] - b[1] + 1)
                    if inter / min(area_a, area_b) >= 1.0 - ratio:
                        if area_a < area_b and dist[i] > dist[j]:
                            occluded[i] = True
                        elif area_b < area_a and dist[j] > dist[i]:
                            occluded[j] = True
        else:
            dist = [np.linalg.norm(np.array(camera) - s[2]) for s in shown]
            for i, (_, a, _) in enumerate(shown):
                mask = np.zeros((a[3] - a[1] + 1, a[2] - a[0] + 1), dtype=bool)
                for j, (_, b, _) in enumerate(shown):
                    if dist[j] < dist[i]:
                        x1, y1 = max(a[0], b[0]) - a[0], max(a[1], b[1]) - a[1]
                        x2, y2 = min(a[2], b[2]) - a[0], min(a[3], b[3]) - a[1]
                        if x1 <= x2 and y1 <= y2:
                            mask[y1:y2 + 1, x1:x2 + 1] = True
                occluded[i] = bool(mask.all())
        out_bb.append([s[1] for s, o in zip(shown, occluded) if not o])
        out_labels.append(np.array([s[0] for s, o in zip(shown, occluded) if not o]))
    return {"bb": out_bb, "labels": out_labels}


def heuristic(perception):
    """HeuristicReasoner.track_for_frame and track_and_predict's output, per frame."""
    classes = perception["classes"]
    snitch = classes.index(SNITCH_CLASS) if SNITCH_CLASS in classes else -1
    large_cones = {i for i, c in enumerate(classes) if c.split("_")[0] == "large" and c.split("_")[2] == "cone"}
    state = {"pos": (-1, 1), "sz": (0, 0), "snitch_box": [-1, -1, -1, -1]}
    stack = []
    snitch_visible = False

    def label_bb(frame, label):
        for d in frame:
            if d[0] == label:
                x1, y1, x2, y2 = d[1:]
                return (x1 + x2) // 2, (y1 + y2) // 2, x2 - x1, y2 - y1, [x1, y1, x2, y2]
        return -1, -1, -1, -1, [-1, -1, -1, -1]

    def update(cx, cy, w, h, label):
        state["pos"], state["sz"], state["label"] = (cx, cy), (w, h), label
        if label == snitch:
            state["object_sz"] = (w, h)

    def closest(frame):
        if not frame:
            raise ValueError("no detection")
        cx, cy = state["pos"]
        def distance(d):
            dx, dy = (d[1] + d[3]) // 2 - cx, (d[2] + d[4]) // 2 - cy
            return math.sqrt(dx * dx + dy * dy)

        best = min(range(len(frame)), key=lambda k: (distance(frame[k]), k))
        return frame[best][0]

    out = []
    for frame in perception["frames"]:
        try:
            cx, cy, w, h, box = label_bb(frame, snitch)
            if cx >= 0 and cy >= 0:
                snitch_visible = True
                state["snitch_box"] = box
                update(cx, cy, w, h, snitch)
                stack = []
            elif not stack:
                snitch_visible = False
                label = closest(frame)
                cx, cy, w, h, _ = label_bb(frame, label)
                update(cx, cy, w, h, label)
                stack.append(snitch)
            else:
                snitch_visible = False
                current = state["label"]
                cx, cy, w, h, _ = label_bb(frame, current)
                if cx < 0 and cy < 0:
                    label = closest(frame)
                    cx, cy, w, h, _ = label_bb(frame, label)
                    update(cx, cy, w, h, label)
                    stack.append(current)
                else:
                    pcx, pcy, pw, ph, _ = label_bb(frame, stack[-1])
                    if pcx >= 0 and pcy >= 0:
                        update(pcx, pcy, pw, ph, stack[-1])
                        stack.pop()
                    else:
                        update(cx, cy, w, h, current)
        except ValueError:
            pass
        if snitch_visible:
            prediction = state["snitch_box"]
        else:
            cx, cy = state["pos"]
            w, h = state["sz"]
            prediction = [int(cx - w / 2), int(cy - h / 2), int(cx + w / 2), int(cy + h / 2)]
            if "object_sz" in state:
                ow, oh = state["object_sz"]
                ocy = cy + 15 if state["label"] in large_cones else cy
                prediction = [int(cx - ow / 2), int(ocy - oh / 2), int(cx + ow / 2), int(ocy + oh / 2)]
        out.append([int(v) for v in prediction])
    return out


def iou(p, g):
    p, g = np.array(p, dtype=float), np.array(g, dtype=float)
    xa, ya = np.maximum(p[:, 0], g[:, 0]), np.maximum(p[:, 1], g[:, 1])
    xb, yb = np.minimum(p[:, 2], g[:, 2]), np.minimum(p[:, 3], g[:, 3])
    inter = np.maximum(xb - xa + 1, 0) * np.maximum(yb - ya + 1, 0)
    area = lambda b: (b[:, 2] - b[:, 0] + 1) * (b[:, 3] - b[:, 1] + 1)
    return inter / (area(p) + area(g) - inter)


def masked_mean(values, frames):
    mask = np.zeros(len(values), dtype=bool)
    mask[[f for f in frames if f < len(values)]] = True
    return None if mask.sum() == 0 else float(np.mean(values[mask]))


def write_perfect_pickles(data, out, union):
    """Writes OPNet's perfect perception pickles of every video of a LA-CATER layout directory
    (scenes/, labels/) into `out`, as OPNet's script saves them (pickle.dump, default protocol)."""
    import pickle
    out.mkdir(parents=True, exist_ok=True)
    for scene_path in sorted((data / "scenes").glob("*.json")):
        scene = json.load(open(scene_path))
        boxes = json.load(open(data / "labels" / (scene_path.stem + "_bb.json")))
        frames = len(next(iter(boxes.values())))
        camera = scene["camera"] if union else None
        with open(out / (scene_path.stem + ".pkl"), "wb") as f:
            pickle.dump(perfect_perception(scene, boxes, frames, camera=camera), f)


def main():
    if sys.argv[1] == "perfect-pickles":
        write_perfect_pickles(Path(sys.argv[2]), Path(sys.argv[3]), sys.argv[4] == "union")
        return
    data, perception_mode, predictions, out_path = Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3]), sys.argv[4]
    result = {"annotations": {}, "heuristic": {}, "analysis": {}}
    for scene_path in sorted((data / "scenes").glob("*.json")):
        if scene_path.stem.endswith("_bb"):
            continue
        video = scene_path.stem
        scene = json.load(open(scene_path))
        boxes = json.load(open(data / "scenes" / (video + "_bb.json")))
        snitch = [[x, y, x + w, y + h] for x, y, w, h in boxes[SNITCH_CLASS + "_" + SNITCH]]
        frames = len(snitch)
        ann = {"contained": contained(scene), "carried": carried(scene), "visible": visible(scene, boxes, frames)}
        result["annotations"][video] = ann
        perception = json.load(open(data / "perception" / f"{video}_{perception_mode}.json"))
        result["heuristic"][video] = heuristic(perception)
        prediction_file = predictions / (video + "_bb.json")
        if prediction_file.exists():
            values = iou(json.load(open(prediction_file)), snitch)
            everything = range(frames)
            occluded = [f for f in everything if f not in set(ann["visible"]) and f not in set(ann["contained"])]
            result["analysis"][video] = {
                "overall": float(np.mean(values)),
                "visible": masked_mean(values, ann["visible"]),
                "occluded": masked_mean(values, occluded),
                "contained": masked_mean(values, ann["contained"]),
                "carried": masked_mean(values, ann["carried"]),
            }
    json.dump(result, open(out_path, "w"))


if __name__ == "__main__":
    main()
