"""
Synthetic stereo images of the tip marker, for simulation and tests.

Each camera's raw image is rendered by ray casting through its lens model: every pixel (sampled
``supersample²`` times, for anti-aliasing at sub-pixel accuracy) is mapped to its ray in the raw
optical frame by inverting the distortion ``D`` (``cv2.undistortPoints``, once per camera on a
grid of ``RAY_GRID`` px, interpolated bilinearly: the distortion is smooth, the interpolation
error stays below 1e-3 px), so the image is distorted as the real lens would distort it. A sphere
covers the samples whose ray passes within its radius; its shade falls off towards the limb
(Lambert, light at the camera). On a textured background (smooth random grey with a blue-green
tint, no red), the marker is then blurred (Gaussian) and sensor noise is added. Distractors
(more spheres, e.g. a red blob) and the backbone (grey anti-aliased polyline, clutter) can be
drawn too.

The background with its noise comes from a small pool rendered once per camera, and only the
marker's region gets fresh noise per frame: a 1280x1024 pair costs a few milliseconds.
"""

from dataclasses import dataclass

from cbha_inverse.vision.stereo import normalized_rays, project_raw
import cv2
import numpy as np

RAY_GRID = 4
"""Spacing [px] of the grid on which each camera's pixel rays are computed exactly."""


@dataclass(frozen=True)
class RenderSettings:
    """
    How the synthetic images look.

    Attributes
    ----------
    marker_radius : float  [m]
        Radius of the tip sphere.
    marker_bgr : (3,) tuple of int
        Colour of the lit sphere (BGR).
    noise_std : float  [DN]
        Standard deviation of the Gaussian sensor noise.
    blur_sigma : float  [px]
        Gaussian blur (optics and sensor); 0 for none.
    supersample : int
        Samples per pixel side.
    noise_pool : int
        Noisy backgrounds kept per camera.

    """

    marker_radius: float = 0.006
    marker_bgr: tuple = (40, 40, 210)
    noise_std: float = 2.0
    blur_sigma: float = 0.7
    supersample: int = 4
    noise_pool: int = 4


def _bilinear_samples(corners, samples):
    """
    Interpolate values given at cell corners at S x S points inside every cell.

    Parameters
    ----------
    corners : (R + 1, C + 1, 2) ndarray
        Values at the corners of R x C cells.
    samples : int
        S: points per cell side, at the fractions ``(j + 0.5) / S``.

    Returns
    -------
    (R, S, C, S, 2) ndarray
        Bilinear interpolation (row-major: cell row, sample row, cell column, sample column).

    """
    weights = (np.arange(samples) + 0.5) / samples
    wv = weights[None, :, None, None, None]
    wu = weights[None, None, None, :, None]

    def corner(rows, cols):
        return corners[rows, cols][:, None, :, None, :]

    low, high = slice(None, -1), slice(1, None)
    return ((1 - wv) * ((1 - wu) * corner(low, low) + wu * corner(low, high))
            + wv * ((1 - wu) * corner(high, low) + wu * corner(high, high)))


def textured_background(width, height, rng):
    """
    Return a smooth random background without red (BGR, uint8).

    Parameters
    ----------
    width, height : int  [px]
        Image size.
    rng : numpy.random.Generator
        Randomness.

    Returns
    -------
    (height, width, 3) ndarray of uint8
        Grey texture at several scales with a blue-green tint (B >= G >= R).

    """
    texture = np.zeros((height, width), np.float32)
    for cells, amplitude in ((6, 45.0), (24, 20.0), (96, 8.0)):
        coarse = rng.uniform(-1.0, 1.0, (max(cells * height // width, 2), cells))
        texture += amplitude * cv2.resize(coarse.astype(np.float32), (width, height),
                                          interpolation=cv2.INTER_CUBIC)
    grey = np.clip(110.0 + texture, 10.0, 230.0)
    return np.clip(np.stack([grey + 12.0, grey + 6.0, grey - 4.0], axis=-1), 0, 255).astype(
        np.uint8)


class CameraRenderer:
    """
    Render spheres and clutter into the raw image of one camera.

    Parameters
    ----------
    camera : CameraModel
        The camera (size, K, D).
    settings : RenderSettings
        Appearance.
    rng : numpy.random.Generator
        Randomness (background texture, noise).

    """

    def __init__(self, camera, settings, rng):
        self.camera = camera
        self.settings = settings
        self.rng = rng
        clean = textured_background(camera.width, camera.height, rng)
        self.clean = clean
        grid_u = np.arange(-0.5, camera.width + RAY_GRID, RAY_GRID)
        grid_v = np.arange(-0.5, camera.height + RAY_GRID, RAY_GRID)
        mesh_u, mesh_v = np.meshgrid(grid_u, grid_v)
        self.grid_rays = normalized_rays(
            camera, np.stack([mesh_u.ravel(), mesh_v.ravel()], -1)).reshape(
            grid_v.size, grid_u.size, 2)
        blurred = self.blur(clean.astype(np.float32))
        self.pool = [np.clip(blurred + rng.normal(0.0, settings.noise_std, blurred.shape), 0,
                             255).astype(np.uint8) for _ in range(max(settings.noise_pool, 1))]

    def rays(self, u, v):
        """
        Return the normalized rays of raw image points (bilinear on the ray grid).

        Parameters
        ----------
        u, v : (N,) ndarray  [px]
            Raw image coordinates inside the image (pixel centres at integers).

        Returns
        -------
        (N, 2) ndarray
            ``(x / z, y / z)`` in the raw optical frame.

        """
        grid = self.grid_rays
        fu, fv = (np.asarray(u) + 0.5) / RAY_GRID, (np.asarray(v) + 0.5) / RAY_GRID
        iu = np.clip(np.floor(fu).astype(int), 0, grid.shape[1] - 2)
        iv = np.clip(np.floor(fv).astype(int), 0, grid.shape[0] - 2)
        au, av = (fu - iu)[:, None], (fv - iv)[:, None]
        return ((1 - av) * ((1 - au) * grid[iv, iu] + au * grid[iv, iu + 1])
                + av * ((1 - au) * grid[iv + 1, iu] + au * grid[iv + 1, iu + 1]))

    def pixel_rays(self):
        """
        Return the rays of every pixel centre (computed once, then cached).

        Returns
        -------
        (height * width, 3) ndarray of float32
            ``(x / z, y / z, 1)`` in the raw optical frame, row by row.

        """
        if getattr(self, '_pixel_rays', None) is None:
            # the pixels of one grid cell sit at the fractions (j + 0.5) / RAY_GRID of the cell
            cells = _bilinear_samples(self.grid_rays, RAY_GRID)
            rows, cols = self.camera.height, self.camera.width
            rays = cells.reshape(cells.shape[0] * RAY_GRID, cells.shape[2] * RAY_GRID, 2)
            rays = rays[:rows, :cols].reshape(-1, 2)
            self._pixel_rays = np.column_stack([rays, np.ones(len(rays))]).astype(np.float32)
        return self._pixel_rays

    def blur(self, image):
        sigma = self.settings.blur_sigma
        return cv2.GaussianBlur(image, (0, 0), sigma) if sigma > 0.0 else image

    def render(self, spheres, polylines=()):
        """
        Render one raw image.

        Parameters
        ----------
        spheres : sequence of ((3,) array_like, float, (3,) tuple)
            ``(centre in the raw optical frame [m], radius [m], BGR colour)`` per sphere, drawn
            far to near.
        polylines : sequence of ((N, 3) array_like, float, (3,) tuple)
            ``(points in the raw optical frame [m], thickness [m], BGR colour)``: clutter drawn
            under the spheres.

        Returns
        -------
        (height, width, 3) ndarray of uint8
            The BGR image.

        """
        image = self.pool[int(self.rng.integers(len(self.pool)))].copy()
        for points, thickness, colour in polylines:
            self._draw_polyline(image, np.asarray(points, float), thickness, colour)
        order = sorted(spheres, key=lambda item: -float(np.asarray(item[0])[2]))
        for centre, radius, colour in order:
            self._draw_sphere(image, np.asarray(centre, float), float(radius), colour)
        return image

    def _region(self, center_px, radius_px, pad):
        half = int(np.ceil(radius_px)) + pad
        u, v = int(round(center_px[0])), int(round(center_px[1]))
        left, top = max(u - half, 0), max(v - half, 0)
        right = min(u + half + 1, self.camera.width)
        bottom = min(v + half + 1, self.camera.height)
        return left, top, right, bottom

    def _draw_sphere(self, image, centre, radius, colour):
        depth = centre[2]
        if not depth > radius:
            return
        center_px = project_raw(self.camera, centre[None])[0]
        focal = float(max(self.camera.camera_matrix[0, 0], self.camera.camera_matrix[1, 1]))
        radius_px = 1.25 * focal * radius / np.sqrt(max(depth * depth - radius * radius, 1e-12))
        blur_pad = int(np.ceil(3.0 * self.settings.blur_sigma)) + 2
        left, top, right, bottom = self._region(center_px, radius_px + 2, blur_pad)
        if right <= left or bottom <= top:
            return
        samples = self.settings.supersample
        rays = self._region_rays(left, top, right, bottom, samples)
        directions = np.column_stack([rays, np.ones(len(rays))])
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        along = directions @ centre
        miss2 = centre @ centre - along * along
        hit = (along > 0.0) & (miss2 < radius * radius)
        shade = np.where(hit, 0.55 + 0.45 * np.sqrt(np.clip(1.0 - miss2 / radius ** 2, 0, 1)),
                         0.0)
        rows, cols = bottom - top, right - left
        coverage = hit.reshape(rows, samples, cols, samples).mean(axis=(1, 3))
        lit = shade.reshape(rows, samples, cols, samples).mean(axis=(1, 3))
        base = self.clean[top:bottom, left:right].astype(np.float32)
        marker = lit[..., None] * np.asarray(colour, np.float32)
        composite = base * (1.0 - coverage[..., None]) + marker
        composite = self.blur(composite)
        noisy = composite + self.rng.normal(0.0, self.settings.noise_std, composite.shape)
        inner = (slice(blur_pad, rows - blur_pad), slice(blur_pad, cols - blur_pad))
        target = image[top:bottom, left:right]
        target[inner] = np.clip(noisy[inner], 0, 255).astype(np.uint8)

    def _region_rays(self, left, top, right, bottom, samples):
        """Return the rays (rows * S * cols * S, 2) of S x S samples per pixel of a region."""
        corner_u, corner_v = np.meshgrid(np.arange(left, right + 1) - 0.5,
                                         np.arange(top, bottom + 1) - 0.5)
        corners = self.rays(corner_u.ravel(), corner_v.ravel()).reshape(
            bottom - top + 1, right - left + 1, 2)
        return _bilinear_samples(corners, samples).reshape(-1, 2)

    def _draw_polyline(self, image, points, thickness, colour):
        points = points[points[:, 2] > 0.05]
        if len(points) < 2:
            return
        pixels = project_raw(self.camera, points)
        focal = float(self.camera.camera_matrix[0, 0])
        width_px = max(int(round(focal * thickness / float(np.median(points[:, 2])))), 1)
        shift = 4
        scaled = np.round(pixels * (1 << shift)).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(image, [scaled], False, tuple(int(c) for c in colour), width_px,
                      cv2.LINE_AA, shift)


class StereoRenderer:
    """
    Render the tip marker (and optional distractors and backbone) into both cameras of a rig.

    Parameters
    ----------
    rig : StereoRig
        The rig.
    settings : RenderSettings, optional
        Appearance.
    seed : int
        Seed of the texture and the noise.

    """

    def __init__(self, rig, settings=RenderSettings(), seed=0):
        rng = np.random.default_rng(seed)
        self.rig = rig
        self.settings = settings
        self.cameras = (CameraRenderer(rig.left, settings, rng),
                        CameraRenderer(rig.right, settings, rng))

    def render(self, p_base, distractors=(), backbone=None, backbone_radius=0.01,
               distractor_radii=None):
        """
        Render one image pair.

        Parameters
        ----------
        p_base : (3,) array_like  [m]
            Marker centre in ``cbha_base``.
        distractors : sequence of (3,) array_like  [m]
            Centres of more red spheres (clutter that looks like the marker).
        backbone : (n, 3) array_like, optional  [m]
            Backbone frame origins in ``cbha_base``, drawn as a grey tube behind the marker.
        backbone_radius : float  [m]
            Radius of the backbone tube.
        distractor_radii : sequence of float, optional  [m]
            Radius of each distractor (default: the marker's).

        Returns
        -------
        left, right : (height, width, 3) ndarray of uint8
            BGR raw images.

        """
        settings = self.settings
        centres_base = np.vstack([np.asarray(p_base, float).reshape(1, 3)]
                                 + [np.asarray(d, float).reshape(1, 3) for d in distractors])
        p_left = self.rig.left_from_base(centres_base)
        frames = [p_left, self.rig.right_from_left(p_left)]
        lines = [[], []]
        if backbone is not None:
            spine_left = self.rig.left_from_base(backbone)
            for index, spine in enumerate((spine_left, self.rig.right_from_left(spine_left))):
                lines[index].append((spine, 2.0 * backbone_radius, (120, 125, 128)))
        radii = [settings.marker_radius] + list(
            [settings.marker_radius] * len(distractors) if distractor_radii is None
            else distractor_radii)
        images = []
        for renderer, centres, polylines in zip(self.cameras, frames, lines):
            spheres = [(c, r, settings.marker_bgr) for c, r in zip(centres, radii)]
            images.append(renderer.render(spheres, polylines))
        return images[0], images[1]


def render_checkerboard(renderer, rotation, origin, pattern, square):
    """
    Render a planar checkerboard into the raw image of one camera (grey, anti-aliased).

    Every pixel's ray (the renderer's lens model) is intersected with the board plane; the
    checker value is box-filtered over the pixel's footprint on the board (a ramp one pixel
    wide across each edge), then blurred and noised like the marker images.

    Parameters
    ----------
    renderer : CameraRenderer
        The camera (rays, blur and noise settings, randomness).
    rotation : (3, 3) array_like
        Board axes (columns: along the pattern's rows, along its columns, normal) in the raw
        optical frame.
    origin : (3,) array_like  [m]
        The board's outer corner (a white margin of one square surrounds the squares) in the
        raw optical frame.
    pattern : (2,) tuple of int
        Inner corners per row and per column (OpenCV's ``patternSize``), e.g. ``(9, 6)``.
    square : float  [m]
        Side of a square.

    Returns
    -------
    (height, width) ndarray of uint8
        The mono image.

    """
    camera = renderer.camera
    columns, rows = pattern[0] + 1, pattern[1] + 1
    rotation = np.asarray(rotation, np.float32)
    origin = np.asarray(origin, np.float32)
    # only the board's bounding box in the image is ray cast; the rest is background
    outline = origin + np.array([[0, 0], [columns + 2, 0], [0, rows + 2], [columns + 2, rows + 2]],
                                np.float32) * square @ rotation[:, :2].T
    left, top, right, bottom = 0, 0, camera.width, camera.height
    if np.all(outline[:, 2] > 0.0):
        pixels = project_raw(camera, outline)
        left, top = np.clip(np.floor(pixels.min(axis=0)).astype(int) - 8, 0, None)
        right = int(np.clip(np.ceil(pixels[:, 0].max()) + 9, left, camera.width))
        bottom = int(np.clip(np.ceil(pixels[:, 1].max()) + 9, top, camera.height))
    directions = renderer.pixel_rays().reshape(camera.height, camera.width, 3)[
        top:bottom, left:right].reshape(-1, 3)
    normal = rotation[:, 2]
    with np.errstate(divide='ignore', invalid='ignore'):
        distance = (normal @ origin) / (directions @ normal)
    hits = directions * distance[:, None] - origin
    board = (hits @ rotation[:, :2]).reshape(bottom - top, right - left, 2) / square - 1.0
    value = np.ones(board.shape[:2], np.float32)
    for axis in range(2):
        coordinate = board[..., axis]
        footprint = np.abs(np.gradient(coordinate, axis=0)) + np.abs(
            np.gradient(coordinate, axis=1))
        fraction = coordinate - np.floor(coordinate)
        edge = np.minimum(fraction, 1.0 - fraction) / np.maximum(footprint, 1e-9)
        parity = np.where(np.floor(coordinate) % 2 == 0, 1.0, -1.0).astype(np.float32)
        value *= parity * np.clip(2.0 * edge, -1.0, 1.0)
    inside = ((board[..., 0] >= 0) & (board[..., 0] <= columns) & (board[..., 1] >= 0)
              & (board[..., 1] <= rows))
    margin = ((board[..., 0] >= -1) & (board[..., 0] <= columns + 1) & (board[..., 1] >= -1)
              & (board[..., 1] <= rows + 1) & (distance.reshape(board.shape[:2]) > 0))
    image = np.full((camera.height, camera.width), 90.0, np.float32)
    crop = np.where(margin, np.float32(235.0), np.float32(90.0))
    image[top:bottom, left:right] = np.where(inside, 125.0 + 110.0 * value, crop)
    image = renderer.blur(image)
    noisy = image + renderer.rng.normal(0.0, renderer.settings.noise_std, image.shape)
    return np.clip(noisy, 0, 255).astype(np.uint8)
