"""The validation cases: geometry, materials, launch, rig and cameras of each CalculiX scene.

Every case is a box meshed with C3D8 hexahedra. CalculiX runs in a "simulation frame" whose
z = 0 plane is the top of the rigid floor or ramp; the world frame of the capture (z up, gravity
-z) is world = ROTATION_WORLD_FROM_SIM @ sim. For the ramp cases the simulation frame is the ramp's
own frame, so the box is meshed square to the ramp and gravity is tilted instead.

Parameters are soft foams and gels: E 1e4-1e5 Pa, nu 0.3-0.4, density 300-400 kg/m^3, sizes
4-24 cm, 0.6-1 s at 60 frames per second.
"""

from dataclasses import dataclass, field

import numpy as np

GRAVITY = 9.81  # [m/s^2], along world -z


def rotation(axis, degrees):
    """Rotation matrix about a coordinate axis ('x', 'y' or 'z')."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


@dataclass
class Material:
    youngs_modulus: float  # [Pa]
    poisson_ratio: float   # [1]
    density: float         # [kg/m^3]


@dataclass
class Camera:
    """Where one pinhole camera looks from, as in softid's camera ring (z up)."""

    target: tuple               # world point at the image centre [m]
    distance: float             # from the target [m]
    elevation: float = 25.0     # above the target's horizontal plane [deg]
    azimuth: float = -90.0      # from +x towards +y [deg]; -90: the camera stands at -y
    width: int = 160            # [px]
    height: int = 120           # [px]
    field_of_view: float = 50.0  # horizontal [deg]


@dataclass
class Case:
    name: str
    description: str
    size: tuple                  # box edge lengths in the body frame [m]
    divisions: tuple             # coarse C3D8 elements along the body axes
    material: Material
    # Optional second material for body x > 0 (two halves split at the body's x = 0 plane).
    second_material: Material = None
    # Rest pose in the simulation frame: sim = body_rotation @ body + centre.
    body_rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    centre: tuple = (0.0, 0.0, 0.1)
    # When set, the centre's z is moved so that the lowest corner is this far above z = 0 [m].
    clearance: float = None
    world_from_sim: np.ndarray = field(default_factory=lambda: np.eye(3))
    floor: bool = True
    # Floor slab extent in the simulation frame [m]: x range, y range (top at z = 0).
    floor_extent: tuple = ((-0.3, 0.3), (-0.3, 0.3))
    friction_coefficient: float = 0.0
    # Clamped layers: nodes with body x below -size_x / 2 + clamp_length are held fixed.
    clamp_length: float = 0.0
    initial_velocity: tuple = (0.0, 0.0, 0.0)          # world frame [m/s], of the centre of mass
    initial_angular_velocity: tuple = (0.0, 0.0, 0.0)  # world frame [rad/s], about it
    duration: float = 0.8   # [s]
    fps: float = 60.0
    cameras: list = field(default_factory=list)

    def divisions_at(self, factor):
        """Element counts refined (factor 2) or coarsened (factor 0.5) from the coarse mesh."""
        return tuple(max(1, int(round(n * factor))) for n in self.divisions)

    @property
    def rest_centre(self):
        """The box centre in the simulation frame [m], after applying the clearance."""
        centre = np.array(self.centre, dtype=float)
        if self.clearance is not None:
            corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
            corners = corners * np.array(self.size) / 2 @ self.body_rotation.T
            centre[2] = self.clearance - corners[:, 2].min()
        return centre

    @property
    def gravity_sim(self):
        return self.world_from_sim.T @ np.array([0.0, 0.0, -GRAVITY])

    @property
    def length(self):
        return max(self.size)


FOAM = Material(youngs_modulus=5.0e4, poisson_ratio=0.35, density=400.0)


def block_drop():
    # Tilted so that an edge lands first and the block rocks: bending and compression both show
    # the stiffness, not only the quasi-static squash of a flat landing. A first design (tilted
    # 20 and 12 degrees about x and y, 5 cm up) landed on a corner and tipped over; undamped, that
    # motion is chaotic: the coarse and fine meshes' surfaces were 10 cm apart after 0.4 s.
    return Case(
        name="block-drop",
        description="foam block dropped tilted onto a rigid floor (frictionless)",
        size=(0.12, 0.08, 0.06), divisions=(6, 4, 3), material=FOAM,
        body_rotation=rotation("y", 10.0),
        centre=(0.0, 0.0, 0.0), clearance=0.04, duration=0.8,
        cameras=[Camera(target=(0.0, 0.0, 0.05), distance=0.55)])


def block_launch():
    case = block_drop()
    case.name = "block-launch"
    case.description = "the same block launched sideways at 0.5 m/s onto a frictionless floor"
    case.initial_velocity = (0.5, 0.15, 0.0)
    case.floor_extent = ((-0.2, 0.7), (-0.25, 0.4))
    case.cameras = [Camera(target=(0.2, 0.05, 0.05), distance=0.75)]
    return case


def ramp_angle_degrees():
    return 25.0


def cube_ramp():
    # The simulation frame is the ramp's: world = R_y(a) sim maps sim +z to the ramp normal
    # (sin a, 0, cos a), a ramp descending towards world +x, and sim +x to the downhill direction
    # (cos a, 0, -sin a). Frictionless, the cube slides ~0.5 m in 0.5 s (g sin 25 deg = 4.1 m/s^2).
    angle = ramp_angle_degrees()
    world_from_sim = rotation("y", angle)
    return Case(
        name="cube-ramp",
        description="soft cube landing tilted on a frictionless 25 degree ramp and sliding down",
        size=(0.08, 0.08, 0.08), divisions=(4, 4, 4),
        material=Material(youngs_modulus=3.0e4, poisson_ratio=0.3, density=300.0),
        # Square to the ramp and 1 cm above it: it lands flat, squashes and slides. Landing on an
        # edge (tilted 6-15 degrees) made the undamped cube rock by +-25 degrees, and with
        # friction tumble over, a chaotic motion that hides friction and stiffness alike.
        centre=(-0.15, 0.0, 0.0), clearance=0.01, world_from_sim=world_from_sim,
        floor_extent=((-0.35, 0.65), (-0.2, 0.2)), duration=0.5,
        cameras=[Camera(target=tuple(world_from_sim @ np.array([0.1, 0.0, 0.04])),
                        distance=0.8)])


def cube_ramp_friction():
    case = cube_ramp()
    case.name = "cube-ramp-friction"
    case.description = "the same cube on the same ramp with Coulomb friction mu = 0.3"
    case.friction_coefficient = 0.3
    return case


def bar_clamped():
    # Clamped over its first 2 cm (as in a vice) and released horizontal: it sags ~6 cm and swings.
    return Case(
        name="bar-clamped",
        description="soft bar clamped at one end, released horizontal, swinging under gravity",
        size=(0.24, 0.04, 0.04), divisions=(24, 4, 4),
        material=Material(youngs_modulus=1.0e5, poisson_ratio=0.3, density=300.0),
        centre=(0.12, 0.0, 0.3), floor=False, clamp_length=0.02, duration=1.0,
        cameras=[Camera(target=(0.12, 0.0, 0.26), distance=0.6)])


def two_material():
    # Tilted about x only, so the body's x = 0 plane stays the world's x = 0 plane and the stiff
    # half is the axis-aligned box x > 0 in the capture's world frame.
    case = block_drop()
    case.name = "two-material"
    case.description = "block of two halves, E 2.5e4 Pa (x < 0) and 1e5 Pa (x > 0), dropped tilted"
    case.material = Material(youngs_modulus=2.5e4, poisson_ratio=0.35, density=400.0)
    case.second_material = Material(youngs_modulus=1.0e5, poisson_ratio=0.35, density=400.0)
    case.body_rotation = rotation("x", 10.0)
    return case


def tumble_throw():
    return Case(
        name="tumble-throw",
        description="small block thrown up with a spin and a tumble, landing on a frictionless floor",
        size=(0.10, 0.06, 0.04), divisions=(5, 3, 2),
        material=Material(youngs_modulus=4.0e4, poisson_ratio=0.4, density=300.0),
        centre=(-0.08, 0.0, 0.10), initial_velocity=(0.3, 0.0, 0.6),
        initial_angular_velocity=(4.0, 3.0, 8.0), duration=0.8,
        floor_extent=((-0.4, 0.5), (-0.35, 0.35)),
        cameras=[Camera(target=(0.05, 0.0, 0.08), distance=0.6)])


def tiny_drop():
    """The CI check's case (tests/validation): a few seconds of ccx, 0.25 s of motion."""
    return Case(
        name="tiny-drop",
        description="small block dropped tilted onto a frictionless floor (CI check)",
        size=(0.06, 0.04, 0.03), divisions=(3, 2, 2), material=FOAM,
        body_rotation=rotation("x", 15.0), centre=(0.0, 0.0, 0.0), clearance=0.03,
        duration=0.25, cameras=[Camera(target=(0.0, 0.0, 0.03), distance=0.35, width=96, height=72)])


# The validation set proper.
DEFAULT_CASES = ("block-drop", "block-launch", "cube-ramp", "cube-ramp-friction", "bar-clamped",
                 "two-material", "tumble-throw")
CASES = {c().name: c for c in (block_drop, block_launch, cube_ramp, cube_ramp_friction,
                               bar_clamped, two_material, tumble_throw, tiny_drop)}
