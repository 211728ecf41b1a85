"""One validation case end to end: reference stiffness, CalculiX motion, captures."""

import json
import os
import time
import zlib

import numpy as np

from . import capture, ccx_deck, ccx_run, hexmesh, stiffness

RESOLUTIONS = {"coarse": 1, "fine": 2}  # refinement factor of the case's coarse divisions


class FrameTimeError(RuntimeError):
    pass


def frame_times(case):
    """The camera frames' times [s] after t = 0: what every motion.dat must print."""
    frames = int(round(case.duration * case.fps))
    return np.arange(1, frames + 1) / case.fps


def _on_frames(case, times):
    expected = frame_times(case)
    return len(times) == len(expected) and np.allclose(times, expected, rtol=0, atol=1e-6)


def _motion_record(model, printed):
    """Node positions at t = 0 and at every printed time, as run_motion returns them."""
    displacements = np.stack([np.zeros_like(model.rest_sim)] + [u for _, u in printed])
    times = np.array([t for t, _ in printed])
    return {"model": model, "positions_sim": model.rest_sim[None] + displacements,
            "times": np.concatenate([[0.0], times])}


def run_motion(case, settings, factor, workdir, max_retries=2):
    """Runs the motion on the mesh refined by `factor`; returns positions at every camera frame.

    CalculiX shortens fixed explicit increments on its own when it finds them unstable near
    contact; the printed times then drift off the camera frames. That is detected here and the
    run repeated with twice the increments per frame.
    """
    model = ccx_deck.build_model(case, case.divisions_at(factor))
    substeps = ccx_deck.substeps_per_frame(case, model, settings)
    directory = os.path.join(workdir, f"motion-x{factor}")
    seconds = 0.0
    for attempt in range(max_retries + 1):
        seconds += ccx_run.run(ccx_deck.dynamic_deck(case, model, settings, substeps), directory, "motion")
        printed = ccx_run.read_displacements(os.path.join(directory, "motion.dat"), model.mesh.node_count)
        times = np.array([t for t, _ in printed])
        if _on_frames(case, times):
            break
        if attempt == max_retries:
            raise FrameTimeError(f"{case.name} x{factor}: printed times {times[:5]}... do not fall "
                                 f"on the frames even at {substeps} increments per frame")
        substeps *= 2
    return {**_motion_record(model, printed), "substeps_per_frame": substeps,
            "time_step_s": 1.0 / (case.fps * substeps), "ccx_seconds": seconds,
            "attempts": attempt + 1}


def read_motion(case, factor, workdir):
    """The motion an earlier run_motion left in WORKDIR/motion-xF/motion.dat, or None.

    None when the file is missing or does not hold every camera frame at its time (a run that was
    interrupted, or whose increments drifted off the frames), so that the caller runs it again
    rather than compare a partial motion.
    """
    model = ccx_deck.build_model(case, case.divisions_at(factor))
    path = os.path.join(workdir, f"motion-x{factor}", "motion.dat")
    if not os.path.exists(path):
        return None
    try:
        printed = ccx_run.read_displacements(path, model.mesh.node_count)
    except (ccx_run.CcxError, IndexError, ValueError):
        return None  # truncated mid-block, or another mesh's output
    if not _on_frames(case, np.array([t for t, _ in printed])):
        return None
    return _motion_record(model, printed)


def _shared_surface_distances(coarse, fine):
    """(frames, nodes) distances [m] between the two motions at the coarse mesh's surface nodes.

    Every coarse node (i, j, k) is the fine node (2i, 2j, 2k), so the two runs can be compared
    point by point without interpolation.
    """
    mesh_c, mesh_f = coarse["model"].mesh, fine["model"].mesh
    if tuple(mesh_f.divisions) != tuple(2 * n for n in mesh_c.divisions):
        raise ValueError(f"meshes {mesh_c.divisions} and {mesh_f.divisions} are not x2 apart")
    a_all, b_all = coarse["positions_sim"], fine["positions_sim"]
    if len(a_all) != len(b_all):
        raise ValueError(f"motions of {len(a_all)} and {len(b_all)} frames")
    ijk = np.stack(np.meshgrid(*[np.arange(n + 1) for n in mesh_c.divisions], indexing="ij"), -1)
    ijk = ijk.reshape(-1, 3)
    coarse_index = hexmesh.node_index(mesh_c.divisions, *ijk.T)
    fine_index = hexmesh.node_index(mesh_f.divisions, *(2 * ijk).T)
    surface = np.isin(coarse_index, np.unique(hexmesh.surface_quads(mesh_c)))
    a = a_all[:, coarse_index[surface]]
    b = b_all[:, fine_index[surface]]
    return np.linalg.norm(a - b, axis=-1)


def trajectory_difference(coarse, fine):
    """How far the coarse mesh's motion is from the fine one's, at the nodes both meshes share.

    Returns RMS and maximum distances [m] over the surface nodes and all frames, and the RMS per
    frame.
    """
    distance = _shared_surface_distances(coarse, fine)
    per_frame = np.sqrt(np.mean(distance ** 2, axis=1))
    return {"rms_m": float(np.sqrt(np.mean(distance ** 2))), "max_m": float(distance.max()),
            "rms_per_frame_m": [round(float(d), 6) for d in per_frame]}


def surface_distance_per_frame(coarse, fine):
    """Mean and maximum distance [m] per frame between the two motions' shared surface nodes.

    The mean is what a depth camera's noise compares with (every surface point counts once); the
    maximum names the corner or edge where the meshes part first.
    """
    distance = _shared_surface_distances(coarse, fine)
    return {"mean_m": distance.mean(axis=1), "max_m": distance.max(axis=1)}


def case_seed(case_name, seed):
    return zlib.crc32(case_name.encode()) ^ seed


def generate_case(case, resolutions, out_dir, settings, noise, seed=1, log=print):
    """Writes OUT/<case>-<resolution>/ for each resolution; returns the case's summary."""
    factors = [RESOLUTIONS[r] for r in resolutions]
    workdir = os.path.join(out_dir, "work", case.name)
    started = time.monotonic()
    log(f"{case.name}: reference stiffness (*FREQUENCY x1, x2, x3; ringdown {resolutions})")
    reference = stiffness.study(case, settings, workdir, factors)
    summary = {"case": case.name, "description": case.description, "captures": {}}
    motions = {}
    for resolution, factor in zip(resolutions, factors):
        log(f"{case.name}: motion at {resolution} (x{factor})")
        motion = run_motion(case, settings, factor, workdir)
        motions[resolution] = motion
        folder = os.path.join(out_dir, f"{case.name}-{resolution}")
        mesh_record = reference["meshes"][f"x{factor}"]
        truth_extra = {
            "settings": settings,
            "generator": {
                "tool": "tools/validation/make_validation_set.py (CalculiX ccx, independent of softid)",
                "resolution": resolution,
                "divisions": list(motion["model"].mesh.divisions),
                "elements": motion["model"].mesh.element_count,
                "nodes": motion["model"].mesh.node_count,
                "substeps_per_frame": motion["substeps_per_frame"],
                "time_step": motion["time_step_s"],
                "ccx_seconds": round(motion["ccx_seconds"], 2),
                "noise": noise.to_json(),
                "seed": case_seed(case.name, seed),
            },
            "reference": {
                "effective_youngs_modulus": mesh_record["effective_youngs_modulus"][0],
                "effective_youngs_modulus_per_material": mesh_record["effective_youngs_modulus"],
                "stiffness_scale": mesh_record["stiffness_scale"],
                "this_mesh": f"x{factor}",
                "solver": {"ccx": "CalculiX 2.20", **settings.to_json(),
                           "contact_stiffness": ccx_deck.contact_stiffness(case, settings)},
                **reference,
            },
        }
        rng = np.random.default_rng(case_seed(case.name, seed) + factor)
        stats = capture.write_capture(folder, case, motion["model"], motion["positions_sim"],
                                      case.cameras, noise, rng, truth_extra)
        np.save(os.path.join(workdir, f"motion-x{factor}", "positions_sim.npy"), motion["positions_sim"])
        summary["captures"][resolution] = {
            "folder": folder, "ccx_seconds": round(motion["ccx_seconds"], 2),
            "substeps_per_frame": motion["substeps_per_frame"],
            "effective_youngs_modulus": mesh_record["effective_youngs_modulus"], **stats}
    if len(motions) == 2:
        summary["coarse_to_fine_surface_distance"] = trajectory_difference(motions["coarse"],
                                                                           motions["fine"])
    summary["nominal_youngs_modulus"] = [m.youngs_modulus for m in
                                         [case.material] + ([case.second_material] if case.second_material else [])]
    summary["frequency_extrapolated_hz"] = reference["frequency_extrapolated_hz"]
    summary["observed_order"] = reference["observed_order"]
    summary["stiffness_scales"] = {k: v["stiffness_scale"] for k, v in reference["meshes"].items()}
    summary["seconds"] = round(time.monotonic() - started, 1)
    with open(os.path.join(workdir, "summary.json"), "w") as f:
        json.dump(summary, f, indent=1)
    return summary
