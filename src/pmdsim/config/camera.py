"""``[camera]``: the pinhole or calibrated (OpenCV) camera, its pose and optics."""

from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from .base import (Coord, Float, Int, Length, PositiveFloat, ResolutionAxis, Vec3, _Model,
    _nonzero_vector, _unit)


#: The widest diagonal field of view of a pinhole camera that is accepted (deg): beyond it
#: the image plane is ~25 focal lengths across, a unit slip (38.4 um of pitch as 38.4 mm
#: gives 179.8 deg on Fig. 3's camera), not a lens (a rectilinear lens stops near 130 deg).
MAX_FIELD_OF_VIEW_DEG = 175.0


class CameraConfig(_Model):
    """Pinhole (``projection = "perspective"``) or object-side telecentric camera. Pose by
    ``position_mm`` + ``look_at_mm`` + ``up``, or by an explicit ``rotation`` (3x3, columns
    = camera x (right), y (down), z (viewing direction) in world coordinates, OpenCV
    convention). A telecentric camera's ``position_mm`` is a point of its optical axis on
    its entrance plane: every vision ray starts on that plane (normal to the axis) and runs
    parallel to the axis; ``magnification`` / ``pixel_pitch_mm`` is its scale (px per mm on
    the part)."""

    resolution: tuple[ResolutionAxis, ResolutionAxis] = Field(
        description="(width, height) in camera pixels"
    )
    focal_length_mm: Length | None = None
    pixel_pitch_mm: Length | None = None
    focal_length_px: Annotated[Float, Field(gt=0, le=1e8)] | None = None
    principal_point_px: tuple[Coord, Coord] | None = Field(
        None, description="(col, row); default: the image centre ((W-1)/2, (H-1)/2)"
    )
    projection: Literal["perspective", "telecentric"] = Field(
        "perspective", description="'perspective': a pinhole or thin lens (vision rays from "
        "the projection centre position_mm); 'telecentric': an object-side telecentric lens "
        "(orthographic: vision rays parallel to the optical axis, from the entrance plane "
        "through position_mm)")
    magnification: Annotated[Float, Field(gt=0, le=1e4)] | None = Field(
        None, description="telecentric only: the lens's magnification (image size / object "
        "size); with pixel_pitch_mm the scale magnification / pixel_pitch_mm px per mm")
    numerical_aperture: Annotated[Float, Field(gt=0, lt=1)] | None = Field(
        None, description="telecentric only: object-side numerical aperture NA; each pixel "
        "then integrates a cone of half-angle asin(NA) about the axis through the plane in "
        "focus (focus_distance_mm from the entrance plane): a depth of field of about "
        "pixel_pitch_mm / (2 NA magnification); none = ideal orthographic rays (infinite "
        "depth of field)")
    position_mm: Vec3
    look_at_mm: Vec3 | None = None
    up: Vec3 = (0.0, 1.0, 0.0)
    rotation: tuple[Vec3, Vec3, Vec3] | None = None
    # --- optics (scene/camera.py, docs/system.md) ---------------------------------------
    camera_matrix: tuple[Vec3, Vec3, Vec3] | None = Field(
        None, description="OpenCV camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (px); "
        "replaces focal_length_px and principal_point_px")
    dist_coeffs: tuple[Float, ...] | None = Field(
        None, description="OpenCV distortion coefficients (k1, k2, p1, p2[, k3]); or give "
        "k1, k2, k3, p1, p2 by name")
    k1: Float = 0.0
    k2: Float = 0.0
    k3: Float = 0.0
    p1: Float = 0.0
    p2: Float = 0.0
    subpixels: Annotated[Int, Field(ge=1, le=16)] = Field(
        1, description="n: each pixel value integrates n x n stratified sub-pixel vision rays "
        "(1 = one ray through the pixel centre)")
    f_number: Annotated[Float, Field(ge=0.5, le=1e4)] | None = Field(
        None, description="thin lens of focal_length_mm at this f-number (aperture diameter "
        "focal_length_mm / f_number; >= 0.5, a numerical aperture <= 1); none = pinhole")
    focus_distance_mm: PositiveFloat | None = Field(
        None, description="distance of the plane in focus along the optical axis; default: the "
        "surface point seen by the image centre")
    aperture_samples: Annotated[Int, Field(ge=1, le=100_000)] = Field(
        16, description="stratified aperture samples per sub-pixel (thin lens only)")
    aperture_seed: Annotated[Int, Field(ge=0, lt=2**63)] = 0
    roi: tuple[Annotated[Int, Field(ge=0)], Annotated[Int, Field(ge=0)], ResolutionAxis, ResolutionAxis] | Literal["auto"] | None = Field(
        None, description="region of interest (col0, row0, width, height) of the sensor that "
        "is rendered; 'auto': the smallest window holding every pixel that sees the surface "
        "(plus a margin); none = the whole sensor")

    _up = field_validator("up")(_nonzero_vector)

    def cropped(self, roi=None) -> "CameraConfig":
        """This camera with the window ``roi`` (default: its own, a tuple) as its sensor:
        resolution = the window, principal point (or camera_matrix) moved by its corner,
        ``roi`` None. The same rays through the same pixels, numbered from the corner."""
        roi = self.roi if roi is None else roi
        if roi is None or roi == "auto":
            return self
        c0, r0, w, h = roi
        upd: dict = {"resolution": (w, h), "roi": None}
        if self.camera_matrix is not None:
            k = [list(r) for r in self.camera_matrix]
            k[0][2] -= c0
            k[1][2] -= r0
            upd["camera_matrix"] = tuple(tuple(r) for r in k)
        else:
            fw, fh = self.resolution
            cx, cy = self.principal_point_px or ((fw - 1) / 2.0, (fh - 1) / 2.0)
            upd["principal_point_px"] = (cx - c0, cy - r0)
        return self.model_copy(update=upd)

    @property
    def rendered_resolution(self) -> tuple[int, int]:
        """(width, height) of what is rendered: the window of ``roi``, else the sensor
        (also for ``roi = "auto"`` until it is resolved: an upper bound)."""
        if isinstance(self.roi, tuple):
            return (self.roi[2], self.roi[3])
        return tuple(self.resolution)

    def _check_field_of_view(self) -> None:
        """A pinhole's diagonal field of view beyond :data:`MAX_FIELD_OF_VIEW_DEG` is a unit
        slip (a pitch in um given as mm, a focal length in m), not a PMD camera. A
        telecentric camera has no angular field (its field is mm on the part)."""
        if self.projection == "telecentric":
            return
        w, h = self.resolution
        if self.camera_matrix is not None:
            fx, fy = self.camera_matrix[0][0], self.camera_matrix[1][1]
            what = "camera_matrix"
        elif self.focal_length_px is not None:
            fx = fy = self.focal_length_px
            what = f"focal_length_px = {self.focal_length_px:g}"
        else:
            fx = fy = self.focal_length_mm / self.pixel_pitch_mm
            what = (f"focal_length_mm = {self.focal_length_mm:g} over pixel_pitch_mm = "
                    f"{self.pixel_pitch_mm:g} (a sensor of {w * self.pixel_pitch_mm:.4g} x "
                    f"{h * self.pixel_pitch_mm:.4g} mm)")
        fov = 2 * math.degrees(math.atan(math.hypot(w / (2 * fx), h / (2 * fy))))
        if fov > MAX_FIELD_OF_VIEW_DEG:
            raise ValueError(
                f"the camera's field of view is {fov:.4g} deg across the diagonal ({what}, "
                f"{w} x {h} px), beyond the {MAX_FIELD_OF_VIEW_DEG:g} deg a pinhole camera can "
                "image: check the units (pixel_pitch_mm is in mm: 3.45 um = 0.00345; "
                "focal_length_mm in mm)")

    @model_validator(mode="after")
    def _check(self) -> "CameraConfig":
        if self.projection == "telecentric":
            self._check_telecentric()
        else:
            for name in ("magnification", "numerical_aperture"):
                if getattr(self, name) is not None:
                    raise ValueError(f"{name} is for a telecentric camera: set projection = "
                                     "\"telecentric\" or remove it")
        if self.camera_matrix is not None:
            k = np.asarray(self.camera_matrix, float)
            if (k[0, 1] != 0 or k[1, 0] != 0 or k[2, 0] != 0 or k[2, 1] != 0 or k[2, 2] != 1
                    or k[0, 0] <= 0 or k[1, 1] <= 0):
                raise ValueError("camera_matrix must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] "
                                 "with fx, fy > 0 (no skew)")
            if self.focal_length_px is not None or self.principal_point_px is not None:
                raise ValueError("give camera_matrix or focal_length_px/principal_point_px, not both")
        if self.dist_coeffs is not None:
            if len(self.dist_coeffs) not in (4, 5):
                raise ValueError("dist_coeffs must be OpenCV's (k1, k2, p1, p2) or (k1, k2, p1, p2, k3)")
            if any(getattr(self, n) != 0.0 for n in ("k1", "k2", "k3", "p1", "p2")):
                raise ValueError("give dist_coeffs or k1, k2, k3, p1, p2 by name, not both")
        if self.f_number is not None and self.focal_length_mm is None:
            raise ValueError("f_number needs focal_length_mm (the aperture diameter is "
                             "focal_length_mm / f_number)")
        if (self.focus_distance_mm is not None and self.focal_length_mm is not None
                and self.focus_distance_mm <= self.focal_length_mm):
            raise ValueError(f"focus_distance_mm = {self.focus_distance_mm:g} must exceed "
                             f"focal_length_mm = {self.focal_length_mm:g} (a thin lens cannot "
                             "focus nearer than its focal length); give the distance to the "
                             "part in mm")
        has_mm = self.focal_length_mm is not None or self.pixel_pitch_mm is not None
        if self.camera_matrix is not None or self.projection == "telecentric":
            pass
        elif self.focal_length_px is None:
            if self.focal_length_mm is None or self.pixel_pitch_mm is None:
                raise ValueError(
                    "give focal_length_mm and pixel_pitch_mm, or focal_length_px (or camera_matrix)"
                )
        elif has_mm and self.focal_length_mm is not None and self.pixel_pitch_mm is not None:
            if not math.isclose(
                self.focal_length_mm / self.pixel_pitch_mm, self.focal_length_px, rel_tol=1e-9
            ):
                raise ValueError(
                    "focal_length_px contradicts focal_length_mm / pixel_pitch_mm: give one"
                )
        self._check_field_of_view()
        if isinstance(self.roi, tuple):
            c0, r0, w, h = self.roi
            if c0 + w > self.resolution[0] or r0 + h > self.resolution[1]:
                raise ValueError(f"roi = {list(self.roi)} (col0, row0, width, height) reaches beyond "
                                 f"the sensor's {self.resolution[0]} x {self.resolution[1]} px: "
                                 "shrink the window or move its corner")
        if (self.look_at_mm is None) == (self.rotation is None):
            raise ValueError("give exactly one of look_at_mm (with up) or rotation")
        if self.look_at_mm is not None:
            d = np.subtract(self.look_at_mm, self.position_mm)
            if np.linalg.norm(d) < 1e-9:
                raise ValueError("look_at_mm must differ from position_mm")
            _unit("up", self.up)
            if np.linalg.norm(np.cross(d, self.up)) < 1e-9 * np.linalg.norm(d) * np.linalg.norm(self.up):
                raise ValueError("up must not be parallel to the viewing direction")
        else:
            r = np.asarray(self.rotation, float)
            if not np.allclose(r.T @ r, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
                raise ValueError("rotation must be a proper rotation matrix (orthonormal, det +1)")
        return self

    def _check_telecentric(self) -> None:
        """A telecentric camera has a scale in px per mm, no focal length and no thin lens."""
        scale = "give magnification and pixel_pitch_mm"
        for name, why in (("focal_length_mm", f"a telecentric lens has no projection centre: {scale}"),
                          ("focal_length_px", f"{scale} (or camera_matrix in px per mm)"),
                          ("f_number", "its aperture is the object-side numerical_aperture")):
            if getattr(self, name) is not None:
                raise ValueError(f"{name} is not used by projection = \"telecentric\": {why}")
        if self.camera_matrix is None and (self.magnification is None or self.pixel_pitch_mm is None):
            raise ValueError("projection = \"telecentric\" needs magnification and pixel_pitch_mm "
                             "(or camera_matrix with fx, fy in px per mm on the part)")
        if self.camera_matrix is not None and self.magnification is not None:
            raise ValueError("give camera_matrix or magnification/pixel_pitch_mm, not both")
        if self.focus_distance_mm is not None and self.numerical_aperture is None:
            raise ValueError("focus_distance_mm of a telecentric camera needs numerical_aperture "
                             "(without it every depth is in focus)")

    @property
    def focal_px(self) -> float:
        """fx: px per unit normalised coordinate (perspective), px per mm (telecentric)."""
        if self.projection == "telecentric" and self.camera_matrix is None:
            return float(self.magnification / self.pixel_pitch_mm)
        if self.camera_matrix is not None:
            return float(self.camera_matrix[0][0])
        if self.focal_length_px is not None:
            return float(self.focal_length_px)
        return float(self.focal_length_mm / self.pixel_pitch_mm)

    @property
    def has_aperture(self) -> bool:
        """A pixel integrates over an aperture: a thin lens (f_number) or a telecentric
        lens's numerical_aperture."""
        return self.f_number is not None or self.numerical_aperture is not None

    @property
    def vision_rays_per_pixel(self) -> int:
        """Vision rays per pixel: sub-pixels x aperture samples."""
        return self.subpixels ** 2 * (self.aperture_samples if self.has_aperture else 1)

    @property
    def distortion(self) -> tuple[float, float, float, float, float]:
        """OpenCV order (k1, k2, p1, p2, k3)."""
        if self.dist_coeffs is not None:
            d = tuple(float(x) for x in self.dist_coeffs)
            return d + (0.0,) * (5 - len(d))
        return (self.k1, self.k2, self.p1, self.p2, self.k3)
