"""What a site's cameras see of its floor, and the site as `GET /v1/sites/{site}` describes it.

A camera's view is the floor it can place people on: the farthest floor point, in each of 72
directions from its nadir, of a pixel inside the frame and the calibrated field, and no farther than
`MAX_VIEW_M`. A zone outside every camera's view is allowed (a camera may come later) but the site
description reports it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import shapely
from numpy.typing import NDArray

from fisheye import FisheyeCamera, camera_to_dict
from service.sites.store import SiteRecord

FloatArray = NDArray[np.float64]

MAX_VIEW_M = 20.0  # past this, positions from an overhead camera are too coarse to count
_DIRECTIONS = 72
_RADII = 96


def camera_view_m(camera: FisheyeCamera) -> FloatArray:
    """(72, 2) m: the polygon of the floor `camera` sees, in the site frame (its floor frame when it
    has no site pose)."""
    phi = np.linspace(0.0, 2.0 * np.pi, _DIRECTIONS, endpoint=False)
    reach_px = camera.image_circle_radius_px() * np.linspace(0.0, 1.0, _RADII)[1:]
    u0, v0 = camera.principal_point
    u = u0 + reach_px[None, :] * np.cos(phi)[:, None]
    v = v0 - reach_px[None, :] * np.sin(phi)[:, None] * camera.focal_px[1] / camera.focal_px[0]
    width, height = camera.image_size
    inside = (u >= 0) & (u <= width - 1) & (v >= 0) & (v <= height - 1)
    floor = camera.floor_positions(np.stack([u.ravel(), v.ravel()], axis=1))
    distance = floor.distance_m.reshape(_DIRECTIONS, -1)
    usable = inside & np.isfinite(distance) & (distance <= MAX_VIEW_M)
    # The farthest usable sample of each direction (a direction with none keeps the nadir).
    farthest = np.where(usable.any(axis=1), _RADII - 2 - np.argmax(usable[:, ::-1], axis=1), -1)
    xy = floor.xy_m.reshape(_DIRECTIONS, -1, 2)
    outline = np.array([xy[row, column] if column >= 0 else np.zeros(2)
                        for row, column in enumerate(farthest)])
    site = camera.floor_to_site(outline)
    return outline if site is None else site


def zones_out_of_view(record: SiteRecord) -> list[str]:
    """The zones of a site that no camera of it sees any part of."""
    views = [shapely.Polygon(camera_view_m(camera)).buffer(0) for camera in record.cameras]
    seen = shapely.union_all(views) if views else shapely.Polygon()
    return [zone_id for zone_id, zone in record.layout.zones.items() if not zone.shape.intersects(seen)]


def site_to_json(record: SiteRecord) -> dict[str, Any]:
    """The answer of `GET /v1/sites/{site}`."""
    blind = zones_out_of_view(record)
    cameras = []
    for camera in record.cameras:
        pose = camera_to_dict(camera).get("site_pose", {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 0.0})
        cameras.append({"id": camera.id, "site_pose": pose,
                        "view_m": camera_view_m(camera).round(3).tolist()})
    return {
        "id": record.id,
        "cameras": cameras,
        "zones": [{"id": zone_id, **zone.to_dict(), "in_view": zone_id not in blind}
                  for zone_id, zone in record.layout.zones.items()],
        "lines": [{"id": line_id, **line.to_dict()} for line_id, line in record.layout.lines.items()],
        "notes": [f"zone {zone_id!r} lies outside every camera's view: nobody will be counted in it"
                  for zone_id in blind],
    }
