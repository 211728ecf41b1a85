"""Is the reference motion itself converged in the mesh? Frame by frame, the capture's motion
against the same case run on a mesh refined x2 per axis.

Why: the effective Young's modulus (stiffness.py) corrects the reference mesh's stiffness, but
not what a coarse mesh does to an impact. On `tumble-throw`, ccx on the x2 mesh and on the x4 mesh
differ by 0.25 mm mean surface distance at frame 10 (in flight), 1.3 mm at frame 12 (the first
corner landing), 17 mm at frame 14 and 35 mm at frame 16 (x1 against x2 alike): after the landing
the reference is not a converged solution of the continuum, and a fit can only be judged on the
frames before that. This module finds those frames and records them in the capture's truth.json
under reference.motion_check (validate_independent.py --reference-frames fits only them).
"""

import dataclasses
import os

import numpy as np

from . import capture, ccx_deck, ccx_run, generate

# About the captures' depth noise at the camera distance: sigma = 1.5 mm x (z / 1 m)^2 is
# 0.45-0.54 mm at 0.55-0.6 m (block-drop, bar-clamped, tumble-throw). A reference whose mesh
# changes the surface by less than that is as good as converged for a depth camera.
DEFAULT_TOLERANCE_M = 0.5e-3


def capture_motion(case, factor, workdir):
    """The node positions the capture was rendered from (factor 1: coarse, 2: fine).

    generate_case saves them as WORKDIR/motion-xF/positions_sim.npy; without that file they are
    rebuilt from the same folder's motion.dat.
    """
    model = ccx_deck.build_model(case, case.divisions_at(factor))
    directory = os.path.join(workdir, f"motion-x{factor}")
    saved = os.path.join(directory, "positions_sim.npy")
    if os.path.exists(saved):
        positions = np.load(saved)
        if positions.shape[1:] != model.rest_sim.shape:
            raise ValueError(f"{saved}: shape {positions.shape}, the x{factor} mesh has "
                             f"{model.mesh.node_count} nodes")
        return {"model": model, "positions_sim": positions}
    motion = generate.read_motion(case, factor, workdir)
    if motion is None:
        raise FileNotFoundError(f"{directory}: neither positions_sim.npy nor a complete motion.dat "
                                "(make_validation_set.py writes them)")
    return motion


def _first_frames(motion, last_frame):
    """The motion cut after frame `last_frame` (None: all of it)."""
    if last_frame is None:
        return motion
    return {**motion, "positions_sim": motion["positions_sim"][:last_frame + 1]}


def refined_motion(case, settings, factor, workdir, log=print, last_frame=None):
    """The motion at `factor` over frames 0..last_frame (None: all): reused when a motion.dat
    holds those frames, else run with ccx.

    The fine capture's own motion (x2) is the coarse capture's refined one, so after
    `make_validation_set.py --resolution both` the coarse check runs no ccx. With last_frame, ccx
    runs only that far (the explicit scheme's increment does not depend on the duration, so these
    frames are those of the whole run) into WORKDIR/frames-0-K/, never over a whole run's files.
    """
    motion = generate.read_motion(case, factor, workdir)
    directory = workdir
    if motion is None and last_frame is not None:
        case = dataclasses.replace(case, duration=last_frame / case.fps)
        directory = os.path.join(workdir, f"frames-0-{last_frame}")
        motion = generate.read_motion(case, factor, directory)
    if motion is not None:
        log(f"{case.name}: reusing the x{factor} motion in {directory}/motion-x{factor}")
        return _first_frames(motion, last_frame)
    if ccx_run.ccx_binary() is None:
        raise ccx_run.CcxError("ccx not found (apt-get install calculix-ccx)")
    log(f"{case.name}: motion at x{factor} (ccx, {case.duration:.3g} s) for the motion check")
    motion = generate.run_motion(case, settings, factor, directory)
    log(f"{case.name}: x{factor} motion in {motion['ccx_seconds']:.1f} s of ccx, "
        f"{motion['substeps_per_frame']} increments per frame")
    return _first_frames(motion, last_frame)


def converged_last_frame(mean_m, tolerance_m):
    """The last frame k such that every frame 0..k is within the tolerance; -1 when frame 0 is not.

    Frame 0 is the rest pose on both meshes, so in practice k >= 0.
    """
    within = np.asarray(mean_m) <= tolerance_m
    return len(within) - 1 if within.all() else int(np.argmin(within)) - 1


def motion_check_record(coarse, fine, refined_factor, tolerance_m):
    """The truth.json record: per-frame surface distances and the last converged frame."""
    distances = generate.surface_distance_per_frame(coarse, fine)
    return {
        "method": "node positions of this capture's mesh against the same case on a mesh "
                  "refined x2 per axis, at the surface nodes both share, per frame "
                  "(tools/validation/check_reference_motion.py)",
        "refined_factor": refined_factor,
        "tolerance_m": tolerance_m,
        "mean_surface_distance_m": [round(float(d), 9) for d in distances["mean_m"]],
        "max_surface_distance_m": [round(float(d), 9) for d in distances["max_m"]],
        "converged_last_frame": converged_last_frame(distances["mean_m"], tolerance_m),
        # The last frame compared: the capture's last unless the check was cut short (--last-frame).
        "checked_last_frame": len(distances["mean_m"]) - 1,
    }


def summary_line(name, record):
    """One line: the last converged frame and the mean distances there and just after it."""
    last, mean = record["converged_last_frame"], record["mean_surface_distance_m"]
    x = f"x{record['refined_factor'] // 2} vs x{record['refined_factor']}"
    at = ", ".join(f"{mean[k] * 1e3:.3f} mm at frame {k}" for k in (last, last + 1)
                   if 0 <= k < len(mean))
    if last == len(mean) - 1:
        verdict = f"converged over all {len(mean)} frames checked (0-{last})"
    else:
        verdict = f"converged to frame {last} of 0-{len(mean) - 1}"
    return (f"{name}: reference motion {verdict}; mean surface distance {x}: {at} "
            f"(tolerance {record['tolerance_m'] * 1e3:.3g} mm)")


def check_capture(case, resolution, out_dir, settings, tolerance_m=DEFAULT_TOLERANCE_M,
                  last_frame=None, log=print):
    """Checks OUT/<case>-<resolution>/'s reference motion and adds the record to its truth.json.

    last_frame: compare only frames 0..last_frame (a shorter refined run, for the CI check); the
    record's converged_last_frame is then at most that.
    """
    if last_frame is not None and last_frame < 1:
        raise ValueError(f"last_frame {last_frame}: frame 0 is the rest pose, check at least 0-1")
    factor = generate.RESOLUTIONS[resolution]
    folder = os.path.join(out_dir, f"{case.name}-{resolution}")
    workdir = os.path.join(out_dir, "work", case.name)
    truth = capture.read_truth(folder)  # before any ccx: a missing capture fails at once
    coarse = capture_motion(case, factor, workdir)
    if last_frame is not None and last_frame >= len(coarse["positions_sim"]) - 1:
        last_frame = None  # the whole capture
    coarse = _first_frames(coarse, last_frame)
    fine = refined_motion(case, settings, 2 * factor, workdir, log, last_frame)
    record = motion_check_record(coarse, fine, 2 * factor, tolerance_m)
    truth["reference"]["motion_check"] = record
    capture.write_truth(folder, truth)
    log(summary_line(f"{case.name}-{resolution}", record))
    return record
