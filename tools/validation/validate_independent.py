#!/usr/bin/python3
"""Fits softid blind to the independent CalculiX captures and prints how close it comes.

    tools/validation/validate_independent.py --lab build/core/lab/softid-lab --out DIR
        [--cases a,b] [--resolution coarse|fine] [--starts N] [--max-iterations N]
        [--frame-loss squared|cauchy] [--reference-frames]

For each case: generates the capture unless DIR/<case>-<resolution>/ exists (make_validation_set.py),
fits it with the settings a user with a known rig would use (gravity, floor, Poisson ratio and no
damping given; Young's modulus and the launch velocity fitted, and the friction coefficient or the
spin where the case has them), and prints per case the fitted modulus against the nominal value
and against the effective modulus of the reference's own mesh (the truth the capture shows:
tools/validation/README.md), the reported statistical sigma and discretisation error, whether the
truth lies in the reported band (value +- (2 sigma + discretisation error)), how far the
discretisation-corrected value lies from it, and the time. A body of two materials has no single
modulus to compare with: its row names the materials' moduli instead (the diagnosis is its test).
With --diagnose the fit leaves friction out and the diagnosis follows it ("diagnose": true): a second
table says what it named against what the case conceals (friction, two materials, else none) and
its time; the modulus columns are then the base fit's, which misfits where friction is concealed.
With --reference-frames the fit covers only the frames on which the reference motion itself is
converged in the mesh (truth.json's reference.motion_check, check_reference_motion.py).
Writes DIR/validation.json and prints Markdown tables. Use the Debian interpreter /usr/bin/python3.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
CASES = ("block-drop", "block-launch", "cube-ramp", "cube-ramp-friction", "bar-clamped",
         "two-material", "tumble-throw")
KNOWN_CASES = CASES + ("tiny-drop",)  # the CI check's small case, on request only


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--lab", required=True, help="the softid-lab binary")
    parser.add_argument("--out", required=True, help="folder of the captures and results")
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--resolution", choices=["coarse", "fine"], default="coarse",
                        help="the reference mesh whose captures are fitted")
    parser.add_argument("--starts", type=int, default=2)
    parser.add_argument("--max-iterations", type=int, default=50)
    parser.add_argument("--cells", default="auto", help='"auto" (default) or a number')
    parser.add_argument("--element", choices=["trilinear", "incompatible_modes"],
                        default="trilinear", help="the job config's \"element\"")
    parser.add_argument("--grid-orientation", choices=["world", "body"],
                        help="the job config's \"grid_orientation\" (default: the job's "
                             "default, \"body\")")
    parser.add_argument("--cut-cell-samples", type=int, choices=[1, 2, 4, 8],
                        help="the job config's \"cut_cell_samples\" (default: the job's default)")
    parser.add_argument("--frame-loss", choices=["squared", "cauchy"], default="squared",
                        help="the job config's \"cost\": {\"frame_loss\"} (docs/job-config.md)")
    parser.add_argument("--refine-grid", action="store_true",
                        help="the job config's \"refine_grid\": refit on the finer grid where the "
                             "grid moves a value (docs/job-config.md)")
    parser.add_argument("--diagnose", action="store_true",
                        help="leave friction out of the fit and diagnose after it (\"diagnose\": "
                             "true): the diagnosis should name friction and two materials, "
                             "and nothing elsewhere")
    parser.add_argument("--reference-frames", action="store_true",
                        help="fit only frames 0..reference.motion_check.converged_last_frame of "
                             "truth.json (check_reference_motion.py): the frames on which the "
                             "reference motion is converged in its mesh; all frames without it")
    return parser.parse_args(argv)


def expected_decision(truth):
    """What the diagnosis should name when the fit leaves out what the case conceals."""
    if len(truth["reference"].get("effective_youngs_modulus_per_material") or []) > 1:
        return "heterogeneous_stiffness"
    if truth["parameters"]["friction_coefficient"] > 0:
        return "friction"
    return "none"


def reference_last_frame(truth):
    """The last frame on which the reference motion is converged in the mesh, or None unchecked."""
    check = truth["reference"].get("motion_check")
    if check is None:
        return None
    last = check["converged_last_frame"]
    if last < 1:  # -1 would mean "every frame" to the job; 0 leaves nothing to fit
        raise ValueError(f"{truth['scene']}: the reference motion is converged up to frame {last} "
                         "only; nothing to fit")
    return last


def job_config(truth, args):
    """What a user who knows the rig but not the material would send."""
    p = truth["parameters"]
    fit = ["youngs_modulus", "initial_velocity"]
    if p["friction_coefficient"] > 0 and not args.diagnose:
        fit.append("friction_coefficient")
    if any(abs(w) > 0 for w in p["initial_angular_velocity"]):
        fit.append("initial_angular_velocity")
    e = p["youngs_modulus"]
    fixed = {"poisson_ratio": p["poisson_ratio"], "gravity": p["gravity"], "ground": p["ground"],
             "mass_damping": 0.0, "stiffness_damping": 0.0, "contact_damping": 0.0}
    if "friction_coefficient" not in fit:
        fixed["friction_coefficient"] = 0.0
    initial = {"youngs_modulus": {"min": 0.3 * e, "max": 3.0 * e}}
    if "friction_coefficient" in fit:
        initial["friction_coefficient"] = 0.1
    cells = args.cells if args.cells == "auto" else int(args.cells)
    config = {"fit": fit, "fixed": fixed, "initial": initial, "starts": args.starts,
              "max_iterations": args.max_iterations, "cells": cells, "uncertainty": True,
              "element": args.element,
              "diagnose": args.diagnose, "refine_grid": args.refine_grid,
              "cost": {"frame_loss": args.frame_loss}}
    if args.grid_orientation is not None:
        config["grid_orientation"] = args.grid_orientation
    if args.cut_cell_samples is not None:
        config["cut_cell_samples"] = args.cut_cell_samples
    last = reference_last_frame(truth) if args.reference_frames else None
    if last is not None:
        config["frames"] = {"first": 0, "last": last}
    return config


def ensure_capture(case, resolution, out):
    folder = os.path.join(out, f"{case}-{resolution}")
    if not os.path.exists(os.path.join(folder, "capture.json")):
        subprocess.run([sys.executable, os.path.join(HERE, "make_validation_set.py"), "--out", out,
                        "--cases", case, "--resolution", resolution], check=True)
    return folder


def number(entry, *keys):
    for key in keys:
        if not isinstance(entry, dict) or entry.get(key) is None:
            return math.nan
        entry = entry[key]
    return entry if isinstance(entry, (int, float)) else math.nan


def agreeing_frames(discretisation):
    """Leading frames on which the last grid or time-step trial agreed with the finer run (the
    part of the motion the model predicts at the start parameters), or None without a choice."""
    trials = discretisation.get("selection", {}).get("trials", [])
    return trials[-1].get("frames_within_tolerance") if trials else None


def run_case(case, args):
    folder = ensure_capture(case, args.resolution, args.out)
    with open(os.path.join(folder, "truth.json")) as f:
        truth = json.load(f)
    config = job_config(truth, args)
    reference_last = config.get("frames", {}).get("last")
    if args.reference_frames and reference_last is None:
        print(f"{case}: --reference-frames: {folder}/truth.json has no reference.motion_check "
              f"(check_reference_motion.py --out {args.out} --cases {case} --resolution "
              f"{args.resolution}); fitting ALL frames, including any the reference has not "
              "converged on", flush=True)
    elif reference_last is not None:
        print(f"{case}: --reference-frames: fitting frames 0-{reference_last}, on which the "
              "reference motion is converged", flush=True)
    work = os.path.join(args.out, "fits", f"{case}-{args.resolution}")
    os.makedirs(work, exist_ok=True)
    with open(os.path.join(work, "job.json"), "w") as f:
        json.dump(config, f, indent=1)
    started = time.monotonic()
    with open(os.path.join(work, "fit.log"), "w") as log:
        subprocess.run([args.lab, "fit", folder, "-c", os.path.join(work, "job.json"),
                        "-o", os.path.join(work, "result.json")], stdout=log, stderr=log,
                       check=True)
    seconds = time.monotonic() - started
    with open(os.path.join(work, "result.json")) as f:
        result = json.load(f)
    e = result["parameters"]["youngs_modulus"]
    per_material = truth["reference"].get("effective_youngs_modulus_per_material") or []
    # One modulus fitted to a body of several materials has no single truth: the row reports the
    # materials' moduli, and no error or band (the diagnosis is the test of such a capture).
    single_truth = len(per_material) <= 1
    e_eff = truth["reference"]["effective_youngs_modulus"] if single_truth else math.nan
    fitted = e["value"]
    sigma = number(e, "standard_uncertainty")
    bias = number(e, "discretisation_error", "total")
    corrected = number(e, "discretisation_error", "corrected")
    band = 2.0 * (sigma if math.isfinite(sigma) else math.inf) + (bias if math.isfinite(bias) else 0)
    row = {"case": case, "resolution": args.resolution,
           "nominal_youngs_modulus": truth["parameters"]["youngs_modulus"],
           "reference_youngs_modulus": e_eff, "fitted_youngs_modulus": fitted,
           "error_vs_reference": fitted / e_eff - 1.0,
           "error_vs_nominal": (fitted / truth["parameters"]["youngs_modulus"] - 1.0
                                if single_truth else math.nan),
           "reference_youngs_modulus_per_material": per_material,
           "standard_uncertainty": sigma, "discretisation_error": bias,
           "corrected_youngs_modulus": corrected,
           "corrected_error_vs_reference": corrected / e_eff - 1.0,
           # None: the result reports no finite band (an undetermined sigma), which is no success.
           "truth_in_band": (abs(fitted - e_eff) <= band
                             if math.isfinite(band) and single_truth else None),
           "grid_cells": result["grid"]["cells"], "substeps": result["time_step"]["substeps"],
           # --refine-grid: the first fit's grid and value when the result is the finer refit.
           "refined_from_cells": (result["grid_refinement"]["cells"]
                                  if result.get("grid_refinement", {}).get("refined") else None),
           "first_fit_youngs_modulus": (
               result["grid_refinement"]["first_fit"]["parameters"]["youngs_modulus"]["value"]
               if result.get("grid_refinement", {}).get("refined") else None),
           "grid_agrees_frames": agreeing_frames(result["grid"]),
           "step_agrees_frames": agreeing_frames(result["time_step"]),
           # The frames compared: all, or those before the motion turned chaotic.
           "fitted_last_frame": result["time_step"].get("predictable_last_frame"),
           # --reference-frames: the job's last frame (the reference's converged frames), or
           # "unchecked" when truth.json has no motion check; None without the flag.
           "reference_last_frame": (reference_last if reference_last is not None else "unchecked")
                                   if args.reference_frames else None,
           "seconds": round(seconds, 1), "config": config}
    if "friction_coefficient" in result["parameters"]:
        row["fitted_friction"] = result["parameters"]["friction_coefficient"]["value"]
        row["friction"] = truth["parameters"]["friction_coefficient"]
    velocity = result["parameters"]["initial_velocity"]["value"]
    row["velocity_error_m_s"] = math.dist(velocity, truth["parameters"]["initial_velocity"])
    if args.diagnose:
        with open(os.path.join(work, "diagnosis.json")) as f:
            diagnosis = json.load(f)
        row["diagnosis"] = {"decision": diagnosis["decision"],
                            "expected": expected_decision(truth),
                            "findings": [f.get("parameters") for f in diagnosis["findings"]],
                            "seconds": round(diagnosis["seconds"], 1),
                            "screening_seconds": round(diagnosis["screening_seconds"], 1)}
    return row


BAND_WORDS = {True: "yes", False: "no", None: "undetermined"}


def band_words(row):
    if len(row["reference_youngs_modulus_per_material"]) > 1:
        moduli = " / ".join(f"{e / 1e3:.1f}" for e in row["reference_youngs_modulus_per_material"])
        return f"no single truth (materials {moduli} kPa)"
    return BAND_WORDS[row["truth_in_band"]]


def magnitude(x):
    return f"{100 * x:.2g} %" if math.isfinite(x) else "undetermined"


def percent(x):
    return f"{100 * x:+.1f} %" if math.isfinite(x) else "-"


def dash(x):
    return "-" if x is None else str(x)


def fitted_frames(row):
    """"all", or "0-L" when softid left out the frames it cannot predict; with --reference-frames
    also the limit set by the reference's own convergence (its frames 0-N are the job's)."""
    last, reference = row.get("fitted_last_frame"), row.get("reference_last_frame")
    if reference is None:
        return "all" if last is None else f"0-{last}"
    if reference == "unchecked":
        return ("all" if last is None else f"0-{last}") + " (reference unchecked)"
    return f"0-{reference if last is None else min(last, reference)} (reference converged 0-{reference})"


def print_table(rows):
    print("| case | E fitted [kPa] | vs reference mesh | vs nominal | sigma | discretisation "
          "| truth in band | corrected vs reference | grid / substeps "
          "| frames agreeing (grid / step) | frames fitted | launch velocity error [m/s] | friction "
          "| time [s] |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        e = r["fitted_youngs_modulus"]
        friction = (f"{r['fitted_friction']:.3f} (truth {r['friction']})" if "friction" in r else "-")
        print(f"| `{r['case']}` | {e / 1e3:.2f} | {percent(r['error_vs_reference'])} "
              f"| {percent(r['error_vs_nominal'])} | {magnitude(r['standard_uncertainty'] / e)} "
              f"| {magnitude(r['discretisation_error'] / e)} | {band_words(r)} "
              f"| {percent(r['corrected_error_vs_reference'])} "
              f"| {r['grid_cells']} / {r['substeps']} "
              f"| {dash(r['grid_agrees_frames'])} / {dash(r['step_agrees_frames'])} "
              f"| {fitted_frames(r)} "
              f"| {r['velocity_error_m_s']:.3f} | {friction} "
              f"| {r['seconds']:.0f} |")
    judged = [r for r in rows if len(r["reference_youngs_modulus_per_material"]) <= 1]
    print(f"\ntruth in band: {sum(r['truth_in_band'] is True for r in judged)} of {len(judged)} "
          f"cases with a single truth")
    print_diagnosis_table([r for r in rows if "diagnosis" in r])


def print_diagnosis_table(diagnosed):
    if not diagnosed:
        return
    print("\n| case | diagnosis | expected | found | diagnosis time [s] (screening) |")
    print("| --- | --- | --- | --- | --- |")
    for r in diagnosed:
        d = r["diagnosis"]
        found = "; ".join(json.dumps(f) for f in d["findings"] if f) or "-"
        print(f"| `{r['case']}` | {d['decision']} | {d['expected']} | {found} "
              f"| {d['seconds']:.0f} ({d['screening_seconds']:.0f}) |")
    right = sum(diagnosis_right(r["diagnosis"]) for r in diagnosed)
    print(f"\ndiagnosis right: {right} of {len(diagnosed)} (a control is right when it names no "
          "physics: `none`, or `unexplained` where the codes' own difference stays above the noise)")


def diagnosis_right(d):
    """The concealed effect named; on a control, no physics named. A control's base fit misses
    physics another code wrote by more than the depth noise (the two codes differ), so
    `unexplained` -- a mismatch not attributed to physics -- is as right as `none`."""
    if d["expected"] == "none":
        return d["decision"] in ("none", "unexplained")
    return d["decision"] == d["expected"]


def main(argv=None):
    args = parse_args(argv)
    names = [c for c in args.cases.split(",") if c]
    unknown = [c for c in names if c not in KNOWN_CASES]
    if unknown:
        print(f"validate_independent: unknown case(s) {unknown}; known: {list(KNOWN_CASES)}",
              file=sys.stderr)
        return 2
    if not os.access(args.lab, os.X_OK):
        print(f"validate_independent: --lab {args.lab}: not an executable", file=sys.stderr)
        return 2
    rows = []
    for case in names:
        print(f"{case}: fitting ({args.resolution})", flush=True)
        rows.append(run_case(case, args))
        with open(os.path.join(args.out, "validation.json"), "w") as f:
            json.dump({"rows": rows}, f, indent=1)
    print_table(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
