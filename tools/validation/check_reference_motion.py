#!/usr/bin/python3
"""Checks, frame by frame, that the reference motion of each capture is converged in the mesh.

    tools/validation/check_reference_motion.py --out DIR [--cases a,b] [--resolution coarse|fine]
        [--tolerance-mm 0.5] [--last-frame K]

For each capture DIR/<case>-<resolution>/ made by make_validation_set.py (mesh x1 for coarse, x2
for fine), runs the same case on a mesh refined x2 per axis (or reuses DIR/work/<case>/motion-xN/
when its motion.dat already holds every frame, as the fine capture's does for the coarse check),
and measures per frame the mean and maximum distance between the two motions at the surface nodes
both meshes share. The last frame up to which every frame's mean distance stays within the
tolerance goes with the distances into truth.json, under reference.motion_check; fit only those
frames (validate_independent.py --reference-frames): after a landing the reference mesh's own
error can reach centimetres (tumble-throw, x2 against x4: 0.25 mm in flight at frame 10, 1.3 mm at
the first landing at frame 12, 17 mm at frame 14). See tools/validation/README.md.

Needs ccx (unless the refined motion exists) and numpy. Use /usr/bin/python3.
"""

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from softid_validation import cases, ccx_deck, motion_check  # noqa: E402


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, help="the folder make_validation_set.py wrote")
    parser.add_argument("--cases", default=None,
                        help="comma-separated case names (default: every case with a capture at "
                             "this resolution in --out); known: " + ", ".join(cases.CASES))
    parser.add_argument("--resolution", choices=["coarse", "fine"], default="coarse",
                        help="the captures checked: coarse (mesh x1, against x2) or fine (x2, "
                             "against x4: 8 x the fine mesh's nodes, 1.4-2 x its increments)")
    parser.add_argument("--tolerance-mm", type=float,
                        default=motion_check.DEFAULT_TOLERANCE_M * 1e3,
                        help="largest mean surface distance [mm] of a converged frame (default "
                             "%(default)s: about the captures' depth noise at the camera distance, "
                             "sigma = 1.5 mm (z / 1 m)^2 = 0.45-0.54 mm at 0.55-0.6 m)")
    parser.add_argument("--last-frame", type=int, default=None,
                        help="compare only frames 0..K (a shorter refined run, for the CI check; "
                             "converged_last_frame is then at most K)")
    return parser.parse_args(argv)


def has_capture(args, name):
    return os.path.exists(os.path.join(args.out, f"{name}-{args.resolution}", "truth.json"))


def case_names(args):
    if args.cases is not None:
        return [n for n in args.cases.split(",") if n]
    return [n for n in cases.CASES if has_capture(args, n)]


def main(argv=None):
    args = parse_args(argv)
    names = case_names(args)
    unknown = [n for n in names if n not in cases.CASES]
    if unknown:
        print(f"check_reference_motion: unknown case(s) {unknown}; known: {list(cases.CASES)}",
              file=sys.stderr)
        return 2
    missing = [n for n in names if not has_capture(args, n)]
    if missing or not names:
        print(f"check_reference_motion: no {args.resolution} capture in {args.out} for "
              f"{missing or 'any case'} (make_validation_set.py --out {args.out} "
              f"--resolution {args.resolution})", file=sys.stderr)
        return 2
    if args.last_frame is not None and args.last_frame < 1:
        print("check_reference_motion: --last-frame must be at least 1", file=sys.stderr)
        return 2
    settings = ccx_deck.SolverSettings()
    started = time.monotonic()
    for name in names:
        motion_check.check_capture(cases.CASES[name](), args.resolution, args.out, settings,
                                   args.tolerance_mm * 1e-3, args.last_frame,
                                   log=lambda m: print(m, flush=True))
    print(f"done in {time.monotonic() - started:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
