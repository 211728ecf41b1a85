"""CalculiX input decks: the motion (NLGEOM, contact, gravity, launch), the eigenfrequencies, and a
small free vibration ("ringdown") that measures the frequency of the mesh the motion ran on.

All decks describe the body in the simulation frame (see cases.py). The floor or ramp is a
one-element-thick slab of C3D8s whose nodes are all fixed, so it is rigid; its top faces are the
master surface of a penalty contact with every surface node of the body.

Why explicit dynamics: CalculiX 2.20's implicit *DYNAMIC with contact checks energy conservation
at every increment in which contact elements appear ("checkimpacts") and, for these soft bodies
hitting a rigid floor, rejected every landing increment down to 1e-7 s ("too many cutbacks"),
whatever the penalty (10-1000 E/L), the HHT alpha (0 to -0.3) or the contact type. The explicit
central-difference scheme (*DYNAMIC, EXPLICIT) has no such check and is the usual tool for impact.
Its mass matrix is lumped, which is why the effective stiffness of the mesh is measured by a
ringdown with the same scheme and not only by *FREQUENCY (consistent mass).
"""

from dataclasses import dataclass, asdict

import numpy as np

from . import hexmesh
from .cases import GRAVITY as GRAVITY_MAGNITUDE


@dataclass
class SolverSettings:
    """What the reference solver is told. Written into truth.json's "reference"."""

    element: str = "C3D8"  # full-integration trilinear hexahedron
    integrator: str = "explicit central differences (*DYNAMIC, ALPHA=0, EXPLICIT, DIRECT), lumped mass"
    # Node-to-surface penalty: contact pressure per metre of overclosure = factor * E_max / L.
    # softid's default is 100 E / L; the reference floor is 3x stiffer (its compliance is then
    # 0.3 % of the body's). Stiffer still costs time (the explicit step shrinks as 1 / sqrt(k))
    # and changes nothing a depth camera could see.
    contact_stiffness_factor: float = 300.0
    # Stick slope of the regularised Coulomb friction, as a fraction of the contact stiffness.
    # Measured on the cube resting on the 25 degree ramp (mu 0.3, rigid-body slide 184.8 mm in
    # 0.5 s): at 0.1 the stick spring lets every surface node slip freely each time it comes into
    # contact, 218.8 mm (the first 0.1 s slides as if mu were ~0.1); at 0.01, 367 mm; at 1, 194.2
    # mm, as softid's own regularised Coulomb law (194.7 mm; the rest is the cube's compliance).
    # A bouncing cube re-enters contact all the time, so at 0.1 the whole capture slid as if mu
    # were ~0.21.
    stick_slope_fraction: float = 1.0
    # CalculiX's node-to-surface LINEAR law pulls with a small constant tension sigma_inf at
    # small clearances; make it negligible: this fraction of the body's own weight per area.
    tension_fraction: float = 1e-4
    # Explicit time step: this fraction of the contact oscillator's period scale sqrt(rho h / k)
    # (CalculiX itself shortened our increments at 0.39 of it, and kept 0.235), and of the
    # dilatational Courant limit h / c.
    contact_step_fraction: float = 0.25
    courant_fraction: float = 0.5
    frequency_modes: int = 10  # elastic modes asked of *FREQUENCY
    # Element size of the rigid slab [m]: the master surface is flat, so its faces may be much
    # larger than the body's; fewer faces make the contact search of every increment cheaper.
    floor_cell: float = 0.2

    def to_json(self):
        return asdict(self)


@dataclass
class Model:
    """A case meshed at one resolution and placed in the simulation frame."""

    mesh: hexmesh.HexMesh
    rest_sim: np.ndarray          # (n, 3) node positions in the simulation frame [m]
    element_material: np.ndarray  # (n_elements,) 0 = first material, 1 = second
    clamped_nodes: np.ndarray     # 0-based indices


def build_model(case, divisions):
    mesh = hexmesh.make_box_mesh(case.size, divisions)
    rest_sim = mesh.rest_body @ case.body_rotation.T + case.rest_centre
    centroid_x = mesh.rest_body[mesh.elements].mean(axis=1)[:, 0]
    second = case.second_material is not None
    element_material = (centroid_x > 0.0).astype(int) if second else np.zeros(len(centroid_x), int)
    clamped = np.zeros(0, dtype=int)
    if case.clamp_length > 0.0:
        # Exact when clamp_length is a whole number of elements, which the cases ensure.
        clamp_x = -case.size[0] / 2 + case.clamp_length
        clamped = np.flatnonzero(mesh.rest_body[:, 0] <= clamp_x + 1e-9)
    return Model(mesh, rest_sim, element_material, clamped)


def materials(case):
    return [case.material, case.second_material or case.material]


def element_densities(case, model):
    return np.array([materials(case)[m].density for m in model.element_material])


def node_masses(case, model):
    return hexmesh.lumped_node_masses(model.mesh, element_densities(case, model))


def centre_of_mass(case, model, positions):
    masses = node_masses(case, model)
    return masses @ positions / masses.sum()


def initial_node_velocities(case, model):
    """v = v0 + omega x (x - c), in the simulation frame [m/s]."""
    rotate = case.world_from_sim.T
    v0 = rotate @ np.array(case.initial_velocity, dtype=float)
    omega = rotate @ np.array(case.initial_angular_velocity, dtype=float)
    centre = centre_of_mass(case, model, model.rest_sim)
    return v0 + np.cross(omega, model.rest_sim - centre)


def contact_stiffness(case, settings):
    """Penalty slope [Pa/m] of the contact."""
    e_max = max(m.youngs_modulus for m in materials(case))
    return settings.contact_stiffness_factor * e_max / case.length


def dilatational_wave_speed(material):
    e, nu, rho = material.youngs_modulus, material.poisson_ratio, material.density
    return np.sqrt(e * (1 - nu) / (rho * (1 + nu) * (1 - 2 * nu)))


def explicit_time_step(case, model, settings, with_contact):
    """A stable increment [s] for the central-difference scheme (see SolverSettings)."""
    h = float(model.mesh.element_size.min())
    speed = max(dilatational_wave_speed(m) for m in materials(case))
    dt = settings.courant_fraction * h / speed
    if with_contact:
        rho = min(m.density for m in materials(case))
        dt = min(dt, settings.contact_step_fraction * np.sqrt(rho * h / contact_stiffness(case, settings)))
    return dt


def substeps_per_frame(case, model, settings):
    """Increments per camera frame, so that frames fall exactly on increments."""
    frame_dt = 1.0 / case.fps
    return int(np.ceil(frame_dt / explicit_time_step(case, model, settings, case.floor)))


def _lines(values, per_line=8):
    values = list(values)
    return "\n".join(", ".join(str(v) for v in values[i:i + per_line])
                     for i in range(0, len(values), per_line))


def _nodes_block(positions, first_id, nset):
    rows = "\n".join(f"{first_id + i}, {x:.12g}, {y:.12g}, {z:.12g}"
                     for i, (x, y, z) in enumerate(positions))
    return f"*NODE, NSET={nset}\n{rows}\n"


def _elements_block(element_ids, elements, first_node_id, element_type, elset):
    rows = "\n".join(f"{element_id}, " + ", ".join(str(first_node_id + n) for n in nodes)
                     for element_id, nodes in zip(element_ids, elements))
    return f"*ELEMENT, TYPE={element_type}, ELSET={elset}\n{rows}\n"


def _body_blocks(case, model, settings):
    """Nodes, elements, materials and sections of the body (node and element ids start at 1)."""
    mesh = model.mesh
    text = "*HEADING\n" + f"softid validation case {case.name}\n"
    text += _nodes_block(model.rest_sim, 1, "NBODY")
    names = []
    for index, name in ((0, "EBODYA"), (1, "EBODYB")):
        ids = np.flatnonzero(model.element_material == index)
        if len(ids) == 0:
            continue
        names.append(name)
        text += _elements_block(ids + 1, mesh.elements[ids], 1, settings.element, name)
        m = materials(case)[index]
        text += (f"*MATERIAL, NAME=M{name}\n*ELASTIC\n{m.youngs_modulus:.12g}, {m.poisson_ratio:.12g}\n"
                 f"*DENSITY\n{m.density:.12g}\n"
                 f"*SOLID SECTION, ELSET={name}, MATERIAL=M{name}\n")
    text += "*ELSET, ELSET=EBODY\n" + ", ".join(names) + "\n"
    if len(model.clamped_nodes):
        text += "*NSET, NSET=NCLAMP\n" + _lines(model.clamped_nodes + 1) + "\n"
    return text


def _floor_blocks(case, model, settings, top=0.0):
    """The rigid slab under z = top and the contact definition."""
    (x0, x1), (y0, y1) = case.floor_extent
    cell = settings.floor_cell
    # At least 2 x 2 faces: a single-face master surface crashes ccx 2.20 (realloc).
    nx, ny = max(2, int(np.ceil((x1 - x0) / cell))), max(2, int(np.ceil((y1 - y0) / cell)))
    slab = hexmesh.make_box_mesh((x1 - x0, y1 - y0, 0.02), (nx, ny, 1))
    positions = slab.rest_body + np.array([(x0 + x1) / 2, (y0 + y1) / 2, top - 0.01])
    first_node = model.mesh.node_count + 1
    first_element = model.mesh.element_count + 1
    text = _nodes_block(positions, first_node, "NFLOOR")
    text += _elements_block(first_element + np.arange(slab.element_count), slab.elements,
                            first_node, "C3D8", "EFLOOR")
    # The slab's nodes are all fixed, so its material never acts; it only must not shrink the
    # stable explicit increment (a stiff slab would, by its wave speed).
    m = case.material
    text += (f"*MATERIAL, NAME=MFLOOR\n*ELASTIC\n{m.youngs_modulus:.12g}, 0.3\n"
             f"*DENSITY\n{10 * m.density:.12g}\n*SOLID SECTION, ELSET=EFLOOR, MATERIAL=MFLOOR\n")
    top = "\n".join(f"{first_element + e}, S2" for e in range(slab.element_count))
    text += f"*SURFACE, NAME=SFLOOR, TYPE=ELEMENT\n{top}\n"
    surface_nodes = np.unique(hexmesh.surface_quads(model.mesh))
    text += "*NSET, NSET=NSURF\n" + _lines(surface_nodes + 1) + "\n"
    text += "*SURFACE, NAME=SBODY, TYPE=NODE\nNSURF\n"
    k = contact_stiffness(case, settings)
    tension = settings.tension_fraction * case.material.density * GRAVITY_MAGNITUDE * case.length
    text += (f"*SURFACE INTERACTION, NAME=SI\n*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=LINEAR\n"
             f"{k:.6g}, {tension:.6g}\n")
    if case.friction_coefficient > 0.0:
        text += f"*FRICTION\n{case.friction_coefficient:.6g}, {settings.stick_slope_fraction * k:.6g}\n"
    text += "*CONTACT PAIR, INTERACTION=SI, TYPE=NODE TO SURFACE\nSBODY, SFLOOR\n"
    return text


def _boundary_block(case, model, floor):
    lines = []
    if floor:
        lines.append("NFLOOR, 1, 3")
    if len(model.clamped_nodes):
        lines.append("NCLAMP, 1, 3")
    return "*BOUNDARY\n" + "\n".join(lines) + "\n" if lines else ""


def _velocity_block(velocities):
    if not np.any(velocities != 0.0):
        return ""
    rows = "\n".join(f"{n + 1}, {d + 1}, {velocities[n, d]:.12g}"
                     for n in range(len(velocities)) for d in range(3))
    return f"*INITIAL CONDITIONS, TYPE=VELOCITY\n{rows}\n"


def _gravity_line(case):
    g = case.gravity_sim
    magnitude = np.linalg.norm(g)
    d = g / magnitude
    return f"EBODY, GRAV, {magnitude:.12g}, {d[0]:.12g}, {d[1]:.12g}, {d[2]:.12g}\n"


def _explicit_step(dt, total, print_every, gravity_line=""):
    # ALPHA=0: the central-difference scheme, without the numerical damping of the default -0.05.
    # The maximum increment must be given: without it CalculiX 2.20 never advances time.
    text = (f"*STEP, NLGEOM, INC=100000000\n*DYNAMIC, ALPHA=0, EXPLICIT, DIRECT\n"
            f"{dt:.12g}, {total:.12g}, {dt * 1e-4:.12g}, {dt:.12g}\n")
    if gravity_line:
        text += "*DLOAD\n" + gravity_line
    # Fixed increments cannot be combined with TIME POINTS: print every print_every-th increment.
    text += f"*NODE PRINT, NSET=NBODY, FREQUENCY={print_every}\nU\n"
    return text + "*END STEP\n"


def dynamic_deck(case, model, settings, substeps):
    """The whole motion, printed at every camera frame (every `substeps` increments)."""
    text = _body_blocks(case, model, settings)
    if case.floor:
        text += _floor_blocks(case, model, settings)
    text += _boundary_block(case, model, case.floor)
    text += _velocity_block(initial_node_velocities(case, model))
    frames = int(round(case.duration * case.fps))
    dt = 1.0 / (case.fps * substeps)
    return text + _explicit_step(dt, frames * substeps * dt, substeps, _gravity_line(case))


def frequency_deck(case, model, settings):
    """Eigenfrequencies and mode shapes of the body alone: free (6 rigid modes first) or clamped."""
    text = _body_blocks(case, model, settings)
    text += _boundary_block(case, model, floor=False)
    rigid_modes = 0 if len(model.clamped_nodes) else 6
    text += (f"*STEP\n*FREQUENCY\n{settings.frequency_modes + rigid_modes}\n"
             "*NODE PRINT, NSET=NBODY\nU\n*END STEP\n")
    return text


def ringdown_deck(case, model, settings, mode_shape, frequency, periods=4, samples_per_period=48):
    """Free vibration started with velocity along one mode shape (no gravity, no floor).

    The amplitude is 1e-4 of the body's length, so NLGEOM changes nothing measurable and the
    vibration stays in the mode; the frequency measured from it is that of this mesh under the
    same explicit, lumped-mass scheme as the motion.
    """
    omega = 2 * np.pi * frequency
    shape = mode_shape / np.abs(mode_shape).max()
    velocities = shape * 1e-4 * case.length * omega
    text = _body_blocks(case, model, settings)
    text += _boundary_block(case, model, floor=False)
    text += _velocity_block(velocities)
    # The motion's own increment, so that the ringdown measures that scheme's frequency too.
    dt = 1.0 / (case.fps * substeps_per_frame(case, model, settings))
    substeps = max(1, int(round(1.0 / (frequency * samples_per_period) / dt)))
    samples = periods * samples_per_period
    return text + _explicit_step(dt, samples * substeps * dt, substeps), dt * substeps
