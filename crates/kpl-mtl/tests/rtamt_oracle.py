"""Evaluates a batch of STL formulas with RTAMT (offline, discrete time) for the Rust test
`rtamt_oracle.rs`.

Usage: python rtamt_oracle.py BATCH.json RESULTS.json

BATCH.json holds {"cases": [{"spec": "...", "vars": ["p", ...], "trace": {"time": [...], "p": [...]}}]}.
RESULTS.json gets {"rtamt": VERSION, "results": [{"verdicts": [bool, ...]} or {"error": "..."}]}, one
per case, in order: the sign of RTAMT's robustness at every time stamp (the Rust side only makes
traces whose robustness can never be 0).

One process runs the whole batch. Each case gets a fresh specification object: reusing one across
`evaluate` calls leaks operator state from the previous signal (nickovic/rtamt issue #85).
"""

import json
import logging
import sys

import rtamt

try:
    from importlib.metadata import version

    RTAMT_VERSION = version("rtamt")
except Exception:  # pragma: no cover - version lookup is informative only
    RTAMT_VERSION = "unknown"


def evaluate(case):
    spec = rtamt.StlDiscreteTimeSpecification()
    for name in case["vars"]:
        spec.declare_var(name, "float")
    spec.spec = case["spec"]
    spec.parse()
    robustness = spec.evaluate(case["trace"])
    return [rho > 0 for _, rho in robustness]


def main():
    logging.disable(logging.WARNING)
    batch_path, results_path = sys.argv[1], sys.argv[2]
    with open(batch_path) as f:
        batch = json.load(f)
    results = []
    for case in batch["cases"]:
        try:
            results.append({"verdicts": evaluate(case)})
        except Exception as error:  # report per case; the Rust side fails on any error
            results.append({"error": f"{type(error).__name__}: {error}"})
    with open(results_path, "w") as f:
        json.dump({"rtamt": RTAMT_VERSION, "results": results}, f)


if __name__ == "__main__":
    main()
