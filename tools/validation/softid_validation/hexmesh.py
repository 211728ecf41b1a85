"""Structured hexahedral meshes of boxes, in CalculiX's C3D8 node order, and their surfaces.

A box is meshed in its own body frame (centred on the origin, edges along the axes) and then
placed by a rigid pose. Keeping the structured (i, j, k) layout lets us name faces, material
halves and clamped layers exactly, with no geometric tolerance games.
"""

from dataclasses import dataclass

import numpy as np

# CalculiX C3D8 corner order: bottom face (k = 0) counter-clockwise seen from +z, then the top
# face in the same order. Offsets (di, dj, dk) of the eight corners of element (i, j, k).
C3D8_CORNERS = np.array([
    [0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
    [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1],
])

# The six faces of a C3D8 as CalculiX numbers them (S1..S6), each with the axis and side of the
# box boundary it lies on when the element sits at that boundary.
# S1: 1-2-3-4 (z-), S2: 5-8-7-6 (z+), S3: 1-5-6-2 (y-), S4: 2-6-7-3 (x+), S5: 3-7-8-4 (y+),
# S6: 4-8-5-1 (x-).
FACE_OF_SIDE = {("z", 0): "S1", ("z", 1): "S2", ("y", 0): "S3",
                ("x", 1): "S4", ("y", 1): "S5", ("x", 0): "S6"}
AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


@dataclass
class HexMesh:
    """A structured box mesh. Node and element ids are 1-based, as in CalculiX decks."""

    size: np.ndarray          # edge lengths (lx, ly, lz) [m]
    divisions: tuple          # elements along x, y, z
    rest_body: np.ndarray     # (n_nodes, 3) node positions in the body frame [m]
    elements: np.ndarray      # (n_elements, 8) 0-based node indices, C3D8 order
    element_ijk: np.ndarray   # (n_elements, 3) structured index of each element

    @property
    def node_count(self):
        return len(self.rest_body)

    @property
    def element_count(self):
        return len(self.elements)

    @property
    def element_size(self):
        return self.size / np.array(self.divisions)


def node_index(divisions, i, j, k):
    nx, ny, _ = divisions
    return (k * (ny + 1) + j) * (nx + 1) + i


def make_box_mesh(size, divisions):
    """Meshes a box of edge lengths `size` [m], centred on the origin, with `divisions` C3D8s."""
    size = np.asarray(size, dtype=float)
    nx, ny, nz = divisions
    axes = [np.linspace(-s / 2, s / 2, n + 1) for s, n in zip(size, divisions)]
    zz, yy, xx = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    rest = np.stack([xx.ravel(), yy.ravel(), zz.ravel()], axis=1)
    ijk = np.array([(i, j, k) for k in range(nz) for j in range(ny) for i in range(nx)])
    corners = ijk[:, None, :] + C3D8_CORNERS[None, :, :]
    elements = node_index(divisions, corners[..., 0], corners[..., 1], corners[..., 2])
    return HexMesh(size, tuple(divisions), rest, elements, ijk)


def boundary_faces(mesh):
    """The element faces on the box boundary: list of (element index, 'S1'..'S6')."""
    faces = []
    for e, ijk in enumerate(mesh.element_ijk):
        for axis, a in AXIS_INDEX.items():
            if ijk[a] == 0:
                faces.append((e, FACE_OF_SIDE[(axis, 0)]))
            if ijk[a] == mesh.divisions[a] - 1:
                faces.append((e, FACE_OF_SIDE[(axis, 1)]))
    return faces


def surface_quads(mesh):
    """The boundary as quads of node indices, counter-clockwise seen from outside."""
    quads = []
    divisions = mesh.divisions
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        for side in (0, divisions[axis]):
            for a in range(divisions[u]):
                for b in range(divisions[v]):
                    quad = []
                    for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        ijk = [0, 0, 0]
                        ijk[axis], ijk[u], ijk[v] = side, a + du, b + dv
                        quad.append(node_index(divisions, *ijk))
                    # (u, v, axis) is a right-handed cyclic order for axis = x, z and left-handed
                    # for y; flip so that every quad's normal points out of the box.
                    outward = (side > 0) == (axis != 1)
                    quads.append(quad if outward else quad[::-1])
    return np.array(quads)


def split_quads(quads):
    """Two triangles per quad, keeping the orientation."""
    return np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])


def lumped_node_masses(mesh, element_density):
    """Node masses [kg] such that sum(m_i x_i) is exactly the body's first mass moment.

    For a trilinear brick, the integral of each shape function over a rectangular rest element is
    V/8, and sum_i x_i * integral(rho N_i dV0) is the exact mass moment of the deformed body (mass
    is conserved in the total Lagrangian picture). So the centre of mass from these masses is exact,
    not an approximation.
    """
    volume = float(np.prod(mesh.element_size))
    masses = np.zeros(mesh.node_count)
    np.add.at(masses, mesh.elements.ravel(), np.repeat(element_density * volume / 8.0, 8))
    return masses
