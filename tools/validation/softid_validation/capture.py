"""Writing an ordinary softid-capture/1 folder (docs/capture-format.md) and its truth.json."""

import json
import os

import numpy as np

from . import ccx_deck, hexmesh, render
from .cases import GRAVITY


def write_obj(path, vertices, triangles, comment):
    with open(path, "w") as f:
        f.write(f"# {comment}\n")
        for x, y, z in vertices:
            f.write(f"v {x:.9g} {y:.9g} {z:.9g}\n")
        for a, b, c in triangles + 1:
            f.write(f"f {a} {b} {c}\n")


def mesh_volume(vertices, triangles):
    """Signed volume [m^3] of a closed, outward-oriented triangle surface."""
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    return float(np.sum(np.einsum("ij,ij->i", a, np.cross(b, c))) / 6.0)


def fixed_region_world(case, model):
    """World box holding exactly the clamped nodes: tight on the bar's free side, wide elsewhere.

    softid clamps its own grid nodes inside this box, so its +x face must be the clamp plane.
    """
    clamped = model.rest_sim[model.clamped_nodes] @ case.world_from_sim.T
    lo, hi = clamped.min(axis=0) - 0.5, clamped.max(axis=0) + 0.5
    hi[0] = clamped[:, 0].max() + 1e-6
    if not np.allclose(case.body_rotation, np.eye(3)) or not np.allclose(case.world_from_sim, np.eye(3)):
        raise ValueError("fixed_region_world assumes a clamp along the world x axis")
    return {"min": lo.tolist(), "max": hi.tolist()}


def stiffness_field(case, model):
    """softid's stiffness field for the second material: the world box of body x > 0 at rest."""
    if case.second_material is None:
        return {"kind": "uniform"}
    body_x = model.mesh.rest_body[:, 0]
    stiff = (model.rest_sim[body_x >= -1e-12]) @ case.world_from_sim.T
    axis = case.world_from_sim @ case.body_rotation @ np.array([1.0, 0.0, 0.0])
    if not np.allclose(np.abs(axis), [1.0, 0.0, 0.0]):
        raise ValueError("the material split must stay a world x plane")
    lo, hi = stiff.min(axis=0) - 0.5, stiff.max(axis=0) + 0.5
    lo[0] = stiff[:, 0].min()
    scale = case.second_material.youngs_modulus / case.material.youngs_modulus
    return {"kind": "regions", "regions": [{"min": lo.tolist(), "max": hi.tolist(), "scale": scale}]}


def truth_parameters(case, model, settings):
    ground = None
    if case.floor:
        normal = case.world_from_sim @ np.array([0.0, 0.0, 1.0])
        ground = {"normal": normal.tolist(), "offset": 0.0}
    return {
        "youngs_modulus": case.material.youngs_modulus,
        "poisson_ratio": case.material.poisson_ratio,
        "density": case.material.density,
        "mass_damping": 0.0,
        "stiffness_damping": 0.0,
        "gravity": [0.0, 0.0, -GRAVITY],
        "initial_velocity": list(map(float, case.initial_velocity)),
        "initial_angular_velocity": list(map(float, case.initial_angular_velocity)),
        "ground": ground,
        # Same meaning as softid's (pressure per metre of penetration), but CalculiX applies it
        # node to surface, each node carrying its share of the surface area.
        "contact_stiffness": ccx_deck.contact_stiffness(case, settings) if case.floor else 0.0,
        "contact_damping": 0.0,
        "friction_coefficient": case.friction_coefficient,
        "stiffness_field": stiffness_field(case, model),
        "drag_linear": 0.0,
        "drag_quadratic": 0.0,
    }


def write_capture(folder, case, model, positions_sim, cameras, noise, rng, truth_extra):
    """Renders every frame and writes capture.json, object.obj, camX/NNNNNN.png and truth.json.

    positions_sim: (frames, nodes, 3) node positions in the simulation frame, frame k at k / fps.
    """
    os.makedirs(folder, exist_ok=True)
    triangles = hexmesh.split_quads(hexmesh.surface_quads(model.mesh))
    to_world = case.world_from_sim.T
    rest_world = model.rest_sim @ to_world
    # Only the surface nodes go into the OBJ; renumber the triangles onto them.
    used = np.unique(triangles)
    renumber = np.full(model.mesh.node_count, -1)
    renumber[used] = np.arange(len(used))
    write_obj(os.path.join(folder, "object.obj"), rest_world[used], renumber[triangles],
              f"softid validation case {case.name}: rest surface at t = 0, world frame [m]")
    camera_json = []
    object_pixels = []
    for index, spec in enumerate(cameras):
        camera = render.look_at_camera(f"cam{index}", spec)
        os.makedirs(os.path.join(folder, camera.name), exist_ok=True)
        frames = []
        for k, positions in enumerate(positions_sim):
            depth, cosine = render.render_depth(camera, positions @ to_world, triangles)
            image = render.sensor_frame(depth, cosine, noise, rng)
            name = f"{camera.name}/{k:06d}.png"
            render.write_png16(os.path.join(folder, name), image)
            frames.append(name)
            object_pixels.append(int(np.count_nonzero(image)))
        camera_json.append(camera.to_json(noise.depth_scale, frames))
    masses = ccx_deck.node_masses(case, model)
    capture = {"format": "softid-capture/1", "mesh": "object.obj", "fps": case.fps,
               "mass_kg": float(masses.sum()), "cameras": camera_json}
    if len(model.clamped_nodes):
        capture["fixed_region"] = fixed_region_world(case, model)
    with open(os.path.join(folder, "capture.json"), "w") as f:
        json.dump(capture, f, indent=1)
    truth = {"format": "softid-truth/1", "scene": case.name, "description": case.description,
             "parameters": truth_parameters(case, model, truth_extra["settings"])}
    truth.update({k: v for k, v in truth_extra.items() if k != "settings"})
    write_truth(folder, truth)
    return {"frames": len(positions_sim), "object_pixels_mean": float(np.mean(object_pixels)),
            "object_pixels_min": int(np.min(object_pixels))}


def write_truth(folder, truth):
    """Writes FOLDER/truth.json; also used to add records to it later (check_reference_motion.py)."""
    with open(os.path.join(folder, "truth.json"), "w") as f:
        json.dump(truth, f, indent=1, default=_json_default)


def read_truth(folder):
    with open(os.path.join(folder, "truth.json")) as f:
        return json.load(f)


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value)}")
