"""Scores exported streams with py-motmetrics and TrackEval (run by tests/oracles.rs).

It knows the export format only from docs/scoring.md: it takes the Python block of the section
"Scoring an export with other tools" from that file and runs it, so the documented code is the
code under test.

    python oracles.py DOCS BATCH RESULTS

BATCH is a JSON file `{"cases": [{"folder": ..., "max_distance": ..., "zero_distance": ...,
"iou": ...}]}` (`iou`: an export of boxes, scored by IoU with that threshold);
RESULTS gets `{"results": [{metric: value, ...}, ...]}` in the same order, with `null` for values
that are not numbers (0 / 0).
"""

import json
import math
import re
import sys
import warnings


def documented(docs_path):
    text = open(docs_path, encoding="utf-8").read()
    section = text.split("## Scoring an export with other tools", 1)[1]
    blocks = re.findall(r"```python\n(.*?)```", section, re.S)
    code = [b for b in blocks if "def score_export" in b]
    if not code:
        sys.exit("docs/scoring.md has no Python block with `def score_export` in its export section")
    namespace = {}
    exec(code[0], namespace)
    return namespace["score_export"], namespace["score_export_boxes"]


def plain(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, list):
        return [plain(v) for v in value]
    return value


def main():
    docs, batch_path, results_path = sys.argv[1:4]
    score_export, score_export_boxes = documented(docs)
    batch = json.load(open(batch_path, encoding="utf-8"))
    results = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for case in batch["cases"]:
            try:
                if case.get("iou") is not None:
                    scores = score_export_boxes(case["folder"], case["iou"])
                else:
                    scores = score_export(case["folder"], case["max_distance"], case.get("zero_distance"))
                results.append({k: plain(v) for k, v in scores.items()})
            except Exception as e:  # report which case failed, with the error
                results.append({"error": f"{type(e).__name__}: {e}"})
    json.dump({"results": results}, open(results_path, "w", encoding="utf-8"))


main()
