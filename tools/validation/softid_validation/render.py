"""Depth frames of a triangle surface seen by pinhole cameras, with a depth sensor's flaws.

Conventions of softid-capture/1: OpenCV camera axes (x right, y down, z forward), world z up, a
pixel holds the depth along the camera's z axis in units of depth_scale, 0 = no data. Pixel
centres sit at integer coordinates, so the principal point of a W x H image is ((W-1)/2, (H-1)/2).

Noise model (all of it is written into truth.json):
- Gaussian depth noise with sigma = sigma_constant + sigma_quadratic * z^2 (structured-light and
  time-of-flight sensors degrade roughly with the square of the range);
- quantisation to depth_scale;
- dropped pixels where the surface is seen at a grazing angle (no return): certainly below
  cos(angle) = 0.1, never above 0.3, linearly in between; plus a few random dropouts.
"""

from dataclasses import dataclass, asdict

import numpy as np


@dataclass
class NoiseModel:
    depth_scale: float = 1e-4         # [m] per PNG unit
    sigma_constant: float = 0.0       # [m]
    sigma_quadratic: float = 1.5e-3   # [1/m]: 1.5 mm at 1 m
    grazing_cos_drop: float = 0.1     # below: always dropped
    grazing_cos_keep: float = 0.3     # above: never dropped for the angle
    random_dropout: float = 0.01      # probability per object pixel

    def to_json(self):
        return asdict(self)


@dataclass
class PinholeCamera:
    name: str
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    world_from_camera: np.ndarray  # 4x4 rigid pose

    def to_json(self, depth_scale, frames):
        return {"name": self.name, "width": self.width, "height": self.height,
                "fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy,
                "depth_scale": depth_scale,
                "world_from_camera": [float(v) for v in self.world_from_camera.ravel()],
                "frames": frames}


def look_at_camera(name, spec):
    """A camera on softid's ring convention: at `distance` from the target, `elevation` above
    its horizontal plane, `azimuth` from +x towards +y, looking at the target, image up = world up.
    """
    target = np.array(spec.target, dtype=float)
    el, az = np.radians(spec.elevation), np.radians(spec.azimuth)
    eye = target + spec.distance * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, down, forward, eye
    fx = (spec.width / 2.0) / np.tan(np.radians(spec.field_of_view) / 2.0)
    return PinholeCamera(name, spec.width, spec.height, fx, fx,
                         (spec.width - 1) / 2.0, (spec.height - 1) / 2.0, pose)


def render_depth(camera, vertices_world, triangles, near=0.05):
    """Exact ray-cast depth [m] of the nearest triangle per pixel (0: none), and its |cos| to the ray.

    A z-buffer over the triangles: for a planar triangle 1/z is affine in the image coordinates,
    so interpolating 1/z with screen-space barycentric weights gives the exact depth of the ray's
    hit, not an approximation.
    """
    rotation, origin = camera.world_from_camera[:3, :3], camera.world_from_camera[:3, 3]
    p = (vertices_world - origin) @ rotation          # camera frame
    depth = np.full((camera.height, camera.width), np.inf)
    cosine = np.zeros((camera.height, camera.width))
    z = p[:, 2]
    safe_z = np.where(z > near, z, np.nan)
    u = camera.fx * p[:, 0] / safe_z + camera.cx
    v = camera.fy * p[:, 1] / safe_z + camera.cy
    for tri in triangles:
        if np.any(z[tri] <= near):
            continue
        _rasterise(camera, tri, u, v, z, p, depth, cosine)
    depth[~np.isfinite(depth)] = 0.0
    return depth, cosine


def _rasterise(camera, tri, u, v, z, p, depth, cosine):
    a, b, c = tri
    x0, x1 = int(np.ceil(min(u[tri]))), int(np.floor(max(u[tri])))
    y0, y1 = int(np.ceil(min(v[tri]))), int(np.floor(max(v[tri])))
    x0, y0 = max(x0, 0), max(y0, 0)
    x1, y1 = min(x1, camera.width - 1), min(y1, camera.height - 1)
    if x0 > x1 or y0 > y1:
        return
    area = (u[b] - u[a]) * (v[c] - v[a]) - (u[c] - u[a]) * (v[b] - v[a])
    if abs(area) < 1e-12:
        return
    ys, xs = np.mgrid[y0:y1 + 1, x0:x1 + 1]
    w_a = ((u[b] - xs) * (v[c] - ys) - (u[c] - xs) * (v[b] - ys)) / area
    w_b = ((u[c] - xs) * (v[a] - ys) - (u[a] - xs) * (v[c] - ys)) / area
    w_c = 1.0 - w_a - w_b
    inside = (w_a >= -1e-9) & (w_b >= -1e-9) & (w_c >= -1e-9)
    if not inside.any():
        return
    hit = 1.0 / (w_a / z[a] + w_b / z[b] + w_c / z[c])
    region = depth[y0:y1 + 1, x0:x1 + 1]
    closer = inside & (hit < region)
    if not closer.any():
        return
    region[closer] = hit[closer]
    normal = np.cross(p[b] - p[a], p[c] - p[a])
    normal /= np.linalg.norm(normal)
    rays = np.stack([(xs - camera.cx) / camera.fx, (ys - camera.cy) / camera.fy, np.ones_like(hit)], -1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    cosine[y0:y1 + 1, x0:x1 + 1][closer] = np.abs(rays[closer] @ normal)


def sensor_frame(depth, cosine, noise, rng):
    """What the sensor reports: noisy, quantised, with dropouts. Returns uint16 PNG units."""
    hit = depth > 0.0
    sigma = noise.sigma_constant + noise.sigma_quadratic * depth ** 2
    noisy = depth + rng.standard_normal(depth.shape) * sigma
    span = noise.grazing_cos_keep - noise.grazing_cos_drop
    p_drop = np.clip((noise.grazing_cos_keep - cosine) / span, 0.0, 1.0)
    p_drop = 1.0 - (1.0 - p_drop) * (1.0 - noise.random_dropout)
    dropped = rng.random(depth.shape) < p_drop
    units = np.rint(noisy / noise.depth_scale)
    keep = hit & ~dropped & (units >= 1) & (units <= 65535)
    return np.where(keep, units, 0).astype(np.uint16)


def write_png16(path, image):
    import png  # python3-png; imported here so the rest works without it
    with open(path, "wb") as f:
        png.Writer(image.shape[1], image.shape[0], greyscale=True, bitdepth=16).write(f, image.tolist())
