#!/usr/bin/python3
"""Usage: ccx_capture_test.py SOURCE_DIR SOFTID_LAB

The CI check of the independent validation set (tools/validation): generates its smallest case
("tiny-drop", coarse mesh) with CalculiX and checks that
- the generator runs to the end;
- softid loads the capture and fits it (one iteration of `softid-lab fit`);
- every depth frame shows the object at plausible depths, and nothing else;
- the block's centre of mass in ccx's output falls as 0.5 g t^2 until it touches the floor;
- truth.json holds the public parameter names and the reference's effective stiffness;
- the reference motion check (check_reference_motion.py) against the mesh refined x2, over
  frames 0..CHECK_LAST_FRAME only (the whole refined motion would double the test's time): no
  distance at rest or in free fall, where both meshes fall alike, and a last converged frame that
  agrees with the per-frame distances and the tolerance; a second run reuses the refined motion.

Exit code 77 (CTest: skipped) when ccx, numpy or png (python3-png) is missing.
"""

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

SKIP = 77
# Frames 0-6 of tiny-drop: free fall to frame 4, the landing (t = 0.078 s) just before frame 5.
# Their x2 motion costs 7 s of CPU (all 15 frames: 18 s, more than the rest of this test).
CHECK_LAST_FRAME = 6
FREE_FALL_DISTANCE_M = 5e-5  # two meshes of the same rigid box falling under gravity alike
FIT_CONFIG = {"max_iterations": 1, "cells": 8, "substeps": 2, "starts": 1,
              "frames": {"first": 0, "last": 5},
              "fixed": {"poisson_ratio": 0.35, "ground": {"normal": [0, 0, 1], "offset": 0}}}
PUBLIC_NAMES = ("youngs_modulus", "poisson_ratio", "density", "mass_damping", "stiffness_damping",
                "gravity", "initial_velocity", "initial_angular_velocity", "ground",
                "contact_stiffness", "contact_damping", "friction_coefficient", "stiffness_field",
                "drag_linear", "drag_quadratic")


def fail(message):
    print(f"FAIL: {message}", file=sys.stderr)
    sys.exit(1)


def check(condition, message):
    if not condition:
        fail(message)


def requirements_or_skip():
    try:
        import numpy  # noqa: F401
        import png  # noqa: F401
    except ImportError as error:
        print(f"SKIP: {sys.executable} lacks {error.name} (python3-numpy, python3-png)")
        sys.exit(SKIP)
    if shutil.which("ccx") is None:
        print("SKIP: ccx not found (calculix-ccx)")
        sys.exit(SKIP)


def generate(source_dir, out):
    tool = os.path.join(source_dir, "tools", "validation", "make_validation_set.py")
    start = time.monotonic()
    result = subprocess.run([sys.executable, tool, "--out", out, "--cases", "tiny-drop"],
                            capture_output=True, text=True, check=False)
    seconds = time.monotonic() - start
    check(result.returncode == 0, f"generator exit {result.returncode}:\n{result.stdout}\n{result.stderr}")
    print(f"generated tiny-drop in {seconds:.1f} s")


def check_fit(softid_lab, capture, scratch):
    config = os.path.join(scratch, "job.json")
    with open(config, "w") as f:
        json.dump(FIT_CONFIG, f)
    out = os.path.join(scratch, "result.json")
    result = subprocess.run([softid_lab, "fit", capture, "-c", config, "-o", out],
                            capture_output=True, text=True, check=False)
    check(result.returncode == 0, f"softid-lab fit exit {result.returncode}:\n{result.stderr[-2000:]}")
    with open(out) as f:
        value = json.load(f)["parameters"]["youngs_modulus"]["value"]
    check(value > 0, f"fitted E = {value}")
    print(f"softid-lab fit loaded the capture (E after one iteration: {value:.0f} Pa)")


def check_frames(capture):
    import numpy as np
    import png
    with open(os.path.join(capture, "capture.json")) as f:
        meta = json.load(f)
    check(meta["format"] == "softid-capture/1", "capture format")
    camera = meta["cameras"][0]
    pose = np.array(camera["world_from_camera"]).reshape(4, 4)
    target_distance = np.linalg.norm(pose[:3, 3] - np.array([0.0, 0.0, 0.03]))
    for name in camera["frames"]:
        width, height, rows, info = png.Reader(filename=os.path.join(capture, name)).read()
        check((width, height) == (camera["width"], camera["height"]) and info["bitdepth"] == 16,
              f"{name}: {width}x{height}, {info['bitdepth']} bit")
        depth = np.array(list(rows), dtype=float) * camera["depth_scale"]
        hit = depth[depth > 0]
        check(hit.size >= 50, f"{name}: {hit.size} object pixels")
        # The object (6 cm) seen from ~35 cm: every pixel within 10 cm of the target's distance;
        # a drawn floor would reach far beyond.
        check(np.all(np.abs(hit - target_distance) < 0.10),
              f"{name}: depths {hit.min():.3f}..{hit.max():.3f} m, target at {target_distance:.3f} m")
    print(f"{len(camera['frames'])} frames with object pixels at plausible depths")


def coarse_positions(out):
    import numpy as np
    return np.load(os.path.join(out, "work", "tiny-drop", "motion-x1", "positions_sim.npy"))


def airborne_frames(positions):
    """Frames after 0 before contact: the lowest node still above the floor by more than 1 mm."""
    return [k for k in range(1, len(positions)) if positions[k, :, 2].min() > 1e-3
            and all(positions[j, :, 2].min() > 1e-3 for j in range(k))]


def check_free_fall(source_dir, out):
    import numpy as np
    sys.path.insert(0, os.path.join(source_dir, "tools", "validation"))
    from softid_validation import cases, ccx_deck
    case = cases.CASES["tiny-drop"]()
    model = ccx_deck.build_model(case, case.divisions)
    positions = coarse_positions(out)
    masses = ccx_deck.node_masses(case, model)
    com_z = positions[:, :, 2] @ masses / masses.sum()
    times = np.arange(len(positions)) / case.fps
    airborne = airborne_frames(positions)
    check(len(airborne) >= 3, f"only {len(airborne)} frames before contact")
    for k in airborne:
        fallen = com_z[0] - com_z[k]
        expected = 0.5 * cases.GRAVITY * times[k] ** 2
        check(abs(fallen / expected - 1.0) < 0.01,
              f"frame {k}: centre of mass fell {fallen * 1e3:.4f} mm, 0.5 g t^2 = {expected * 1e3:.4f} mm")
    print(f"centre of mass falls as 0.5 g t^2 (within 1 %) over {len(airborne)} frames before contact")


def check_truth(capture):
    with open(os.path.join(capture, "truth.json")) as f:
        truth = json.load(f)
    check(truth["format"] == "softid-truth/1", "truth format")
    missing = [n for n in PUBLIC_NAMES if n not in truth["parameters"]]
    check(not missing, f"truth.json lacks {missing}")
    reference = truth["reference"]
    for key in ("effective_youngs_modulus", "stiffness_scale", "frequency_extrapolated_hz",
                "frequency_study", "solver"):
        check(key in reference, f"truth.json reference lacks {key}")
    scale = reference["stiffness_scale"]
    check(0.5 < scale < 1.5, f"stiffness scale {scale}")
    print(f"truth.json complete; effective E of this mesh {reference['effective_youngs_modulus']:.0f} Pa "
          f"(nominal {truth['parameters']['youngs_modulus']:.0f} Pa)")


def run_motion_check(source_dir, out):
    tool = os.path.join(source_dir, "tools", "validation", "check_reference_motion.py")
    start = time.monotonic()
    result = subprocess.run([sys.executable, tool, "--out", out, "--cases", "tiny-drop",
                             "--resolution", "coarse", "--last-frame", str(CHECK_LAST_FRAME)],
                            capture_output=True, text=True, check=False)
    seconds = time.monotonic() - start
    check(result.returncode == 0,
          f"check_reference_motion exit {result.returncode}:\n{result.stdout}\n{result.stderr}")
    with open(os.path.join(out, "tiny-drop-coarse", "truth.json")) as f:
        return json.load(f), result.stdout, seconds


def check_reference_motion(source_dir, out):
    truth, _, seconds = run_motion_check(source_dir, out)
    record = truth["reference"].get("motion_check")
    check(record is not None, "truth.json has no reference.motion_check")
    for key in ("refined_factor", "tolerance_m", "mean_surface_distance_m",
                "max_surface_distance_m", "converged_last_frame", "checked_last_frame"):
        check(key in record, f"motion_check lacks {key}")
    check(record["refined_factor"] == 2, f"refined_factor {record['refined_factor']}")
    check(record["tolerance_m"] == 5e-4, f"default tolerance {record['tolerance_m']} m")
    mean, peak = record["mean_surface_distance_m"], record["max_surface_distance_m"]
    check(record["checked_last_frame"] == CHECK_LAST_FRAME
          and len(mean) == len(peak) == CHECK_LAST_FRAME + 1,
          f"{len(mean)} mean and {len(peak)} max distances, checked to frame "
          f"{record['checked_last_frame']}, for frames 0-{CHECK_LAST_FRAME}")
    check(all(0 <= m <= p for m, p in zip(mean, peak)), f"mean {mean} above max {peak}")
    check(peak[0] < 1e-9, f"frame 0 (rest on both meshes): max distance {peak[0]} m")
    airborne = [k for k in airborne_frames(coarse_positions(out)) if k <= CHECK_LAST_FRAME]
    check(len(airborne) >= 3, f"only {len(airborne)} checked frames before contact")
    falling = [peak[k] for k in airborne]
    check(max(falling) < FREE_FALL_DISTANCE_M,
          f"free fall (frames {airborne}): max distances {falling} m between the meshes")
    last, tolerance = record["converged_last_frame"], record["tolerance_m"]
    check(all(m <= tolerance for m in mean[:last + 1]),
          f"converged_last_frame {last}, but mean distances {mean[:last + 1]} exceed {tolerance}")
    check(last == CHECK_LAST_FRAME or mean[last + 1] > tolerance,
          f"converged_last_frame {last}, but frame {last + 1} is within tolerance: {mean}")
    check(last >= airborne[-1], f"converged_last_frame {last} before the end of free fall")
    print(f"reference motion check x1 vs x2 in {seconds:.1f} s: converged to frame {last} of "
          f"0-{CHECK_LAST_FRAME}; mean surface distance [mm] "
          + " ".join(f"{m * 1e3:.3f}" for m in mean))
    again, log, seconds = run_motion_check(source_dir, out)
    check("reusing the x2 motion" in log, f"the second check ran ccx again:\n{log}")
    check(again["reference"]["motion_check"] == record, "the second check's record differs")
    print(f"a second check reuses the x2 motion ({seconds:.1f} s)")


def main():
    if len(sys.argv) != 3:
        print(__doc__.split("\n\n")[0], file=sys.stderr)
        return 2
    source_dir, softid_lab = sys.argv[1], sys.argv[2]
    requirements_or_skip()
    scratch = tempfile.mkdtemp(prefix="softid-validation.")
    try:
        out = os.path.join(scratch, "set")
        generate(source_dir, out)
        capture = os.path.join(out, "tiny-drop-coarse")
        check_truth(capture)
        check_frames(capture)
        check_free_fall(source_dir, out)
        check_reference_motion(source_dir, out)
        check_fit(softid_lab, capture, scratch)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
