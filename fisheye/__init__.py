"""FishLoc geometry: Kannala–Brandt fisheye cameras, radius-aligned boxes, calibration files.

numpy-only (plus OpenCV and pydantic); see DESIGN.md for the conventions.
"""

from fisheye.boxes import (
    cepdof_to_radius_aligned,
    cxcywh_to_corners,
    foot_points,
    loaf_to_radius_aligned,
    radial_angles_rad,
    radius_aligned_to_cepdof,
)
from fisheye.calibration import MarkResiduals, RulerFit, RulerFitConfig, fit_ruler_calibration
from fisheye.camera import FisheyeCamera, FloorPoints
from fisheye.camera_file import (
    CalibrationError,
    assumed_camera,
    camera_from_dict,
    camera_from_opencv,
    camera_to_dict,
    load_camera,
    load_cameras,
    read_opencv_calibration,
    save_camera,
)
from fisheye.image_circle import ImageCircle, camera_from_circle, fit_image_circle
from fisheye.letterbox import Letterbox
from fisheye.rotated import polygon_iou, rotated_iou, rotated_nms
from fisheye.ruler_marks import RulerMarks, read_marks_csv, simulate_ruler_marks
from fisheye.site import SitePose, SitePoseFit, fit_site_pose

__all__ = [
    "CalibrationError",
    "FisheyeCamera",
    "FloorPoints",
    "ImageCircle",
    "Letterbox",
    "MarkResiduals",
    "RulerFit",
    "RulerFitConfig",
    "RulerMarks",
    "SitePose",
    "SitePoseFit",
    "assumed_camera",
    "camera_from_circle",
    "camera_from_dict",
    "camera_from_opencv",
    "camera_to_dict",
    "cepdof_to_radius_aligned",
    "cxcywh_to_corners",
    "fit_image_circle",
    "fit_ruler_calibration",
    "fit_site_pose",
    "foot_points",
    "load_camera",
    "load_cameras",
    "loaf_to_radius_aligned",
    "polygon_iou",
    "radial_angles_rad",
    "radius_aligned_to_cepdof",
    "read_marks_csv",
    "read_opencv_calibration",
    "rotated_iou",
    "rotated_nms",
    "save_camera",
    "simulate_ruler_marks",
]
