"""FishLoc sites: people of several overlapping overhead cameras fused on one floor plan and tracked.

Torch-free and service-free (numpy, OpenCV's Kalman filter, shapely): the
service feeds it the frames it serves, and an evaluation can feed it ground-truth detections
directly. The in-process API:

    from sites import SiteObservation, SiteTracker, TrackerConfig, SiteLayout, Zone, CountingLine

    tracker = SiteTracker("hall-a", TrackerConfig(),
                          SiteLayout.of(zones=[Zone("entrance", [[0, 0], [4, 0], [4, 3], [0, 3]])],
                                        lines=[CountingLine("door", [0, 0], [0, 3])]))
    for frame in frames:                       # each camera's frames, in capture_time order per site
        outcome = tracker.update(SiteObservation.of(
            frame.camera_id, frame.capture_time,   # Unix s: the only clock of tracking
            frame.site_xy_m,                       # (N, 2) people in the site frame, m (NaN: no floor point)
            frame.distance_m,                      # (N,) from the camera's nadir (the gate grows with it)
            frame.scores))                         # (N,)
        outcome.track_ids                      # (N,) "hall-a:17" per detection, None until confirmed
        outcome.use                            # "used", "used_late" (replayed in order) or "dropped_late"
    tracker.occupancy()                        # DESIGN.md's occupancy dict at the newest capture_time
    tracker.frames                             # used / used_late / dropped_late counts
    tracker.remove_camera("cam-2")             # a camera moved to another site or deleted

Frames may arrive out of order: up to `TrackerConfig.reorder_window_s` late they are used (the
tracks are rebuilt in capture_time order), later than that they are dropped and counted.

Seam for several processes: `SiteTracker` holds all of a site's state and takes plain, picklable
`SiteObservation`s, so fusion can sit behind a queue or an RPC that carries them from detection
replicas, as long as all of one site's frames reach one tracker (README, "Sites across replicas").
"""

from sites.fusion import TrackerConfig
from sites.layout import CountingLine, LayoutError, SiteLayout, Zone, line_from_body, zone_from_body
from sites.observation import FrameOutcome, SiteObservation
from sites.tracker import FrameCounts, SiteTracker

__all__ = [
    "CountingLine",
    "FrameCounts",
    "FrameOutcome",
    "LayoutError",
    "SiteLayout",
    "SiteObservation",
    "SiteTracker",
    "TrackerConfig",
    "Zone",
    "line_from_body",
    "zone_from_body",
]
