#!/usr/bin/python3
"""Generates softid's independent validation set with CalculiX.

    tools/validation/make_validation_set.py --out DIR [--cases a,b,...] [--resolution coarse|fine|both]
        [--check-motion [--tolerance-mm 0.5]]

For each case: CalculiX eigenfrequencies at three meshes (the reference's own discretisation
error, as an effective Young's modulus), the motion at the chosen resolution(s) with ccx, and an
ordinary capture folder DIR/<case>-<resolution>/ (capture.json, object.obj, cam0/*.png,
truth.json). ccx's own files stay in DIR/work/<case>/. With --check-motion, each capture's motion
is then compared frame by frame with a mesh refined x2 (check_reference_motion.py; truth.json's
reference.motion_check). See tools/validation/README.md.

Needs: ccx (Debian calculix-ccx), numpy (python3-numpy), png (python3-png). Run with the Debian
interpreter /usr/bin/python3. ccx runs single-threaded, one run at a time.
"""

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from softid_validation import cases, ccx_deck, ccx_run, generate, motion_check, render  # noqa: E402


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, help="output folder (kept out of git)")
    parser.add_argument("--cases", default=",".join(cases.DEFAULT_CASES),
                        help="comma-separated case names; known: " + ", ".join(cases.CASES))
    parser.add_argument("--resolution", choices=["coarse", "fine", "both"], default="coarse")
    parser.add_argument("--seed", type=int, default=1, help="seed of the sensor noise")
    parser.add_argument("--noiseless", action="store_true",
                        help="exact depth (still quantised), no dropouts: for debugging")
    parser.add_argument("--check-motion", action="store_true",
                        help="after each capture, check its motion against a mesh refined x2 "
                             "(check_reference_motion.py): the frames on which the reference "
                             "is converged, in truth.json")
    parser.add_argument("--tolerance-mm", type=float,
                        default=motion_check.DEFAULT_TOLERANCE_M * 1e3,
                        help="with --check-motion: largest mean surface distance [mm] of a "
                             "converged frame (default %(default)s, about the depth noise)")
    return parser.parse_args(argv)


def main(argv=None):
    args = parse_args(argv)
    if ccx_run.ccx_binary() is None:
        print("make_validation_set: ccx not found (apt-get install calculix-ccx)", file=sys.stderr)
        return 2
    names = [n for n in args.cases.split(",") if n]
    unknown = [n for n in names if n not in cases.CASES]
    if unknown:
        print(f"make_validation_set: unknown case(s) {unknown}; known: {list(cases.CASES)}",
              file=sys.stderr)
        return 2
    resolutions = ["coarse", "fine"] if args.resolution == "both" else [args.resolution]
    noise = render.NoiseModel()
    if args.noiseless:
        noise = render.NoiseModel(sigma_quadratic=0.0, random_dropout=0.0, grazing_cos_drop=-1.0,
                                  grazing_cos_keep=0.0)
    settings = ccx_deck.SolverSettings()
    os.makedirs(args.out, exist_ok=True)
    summaries = []
    started = time.monotonic()
    for name in names:
        summary = generate.generate_case(cases.CASES[name](), resolutions, args.out, settings,
                                         noise, args.seed, log=log)
        summaries.append(summary)
        print(_summary_line(summary), flush=True)
        if args.check_motion:
            for resolution in resolutions:  # coarse first: it reuses the fine capture's x2 motion
                motion_check.check_capture(cases.CASES[name](), resolution, args.out, settings,
                                           args.tolerance_mm * 1e-3, log=log)
    _merge_summary(os.path.join(args.out, "summary.json"), summaries)
    print(f"done in {time.monotonic() - started:.0f} s", flush=True)
    return 0


def log(message):
    print(message, flush=True)


def _merge_summary(path, summaries):
    """Adds or replaces these cases in OUT/summary.json, so that partial reruns keep the rest."""
    merged = {}
    if os.path.exists(path):
        with open(path) as f:
            merged = {s["case"]: s for s in json.load(f)["cases"]}
    merged.update({s["case"]: s for s in summaries})
    order = list(cases.CASES)
    with open(path, "w") as f:
        json.dump({"cases": sorted(merged.values(), key=lambda s: order.index(s["case"]))}, f, indent=1)


def _summary_line(summary):
    parts = [f"{summary['case']}: E nominal {summary['nominal_youngs_modulus']}"]
    for resolution, record in summary["captures"].items():
        e_eff = ", ".join(f"{e:.4g}" for e in record["effective_youngs_modulus"])
        parts.append(f"{resolution}: E_eff {e_eff} Pa, ccx {record['ccx_seconds']} s, "
                     f"{record['object_pixels_mean']:.0f} object px/frame")
    return "; ".join(parts) + f" ({summary['seconds']} s)"


if __name__ == "__main__":
    sys.exit(main())
