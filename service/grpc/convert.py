"""Conversions between the pipeline's result / camera records and the gRPC messages.

A gRPC answer is built from the same JSON dict as the REST answer (`result_to_json`), so both
front ends give the same numbers for the same frame, and `response_to_json` turns it back into that
dict (what the gateway prints).
"""

from __future__ import annotations

from typing import Any

from contract import ModelInfo
from fisheye import FisheyeCamera, camera_from_dict, camera_to_dict
from protos.fishloc.v1 import localizer_pb2 as pb
from service.result import DetectionResult, result_to_json

Status = pb.DetectResponse.Status


def _point(pair: list[float] | None) -> pb.Point | None:
    return None if pair is None else pb.Point(x=pair[0], y=pair[1])


def _pair(message: Any, field: str) -> list[float] | None:
    if not message.HasField(field):
        return None
    point = getattr(message, field)
    return [point.x, point.y]


def detection_from_json(item: dict[str, Any]) -> pb.Detection:
    message = pb.Detection(
        score=item["score"], box=pb.Box(**item["box"]),
        corners=[pb.Point(x=x, y=y) for x, y in item["corners"]],
        foot_px=_point(item["foot_px"]), position_m=_point(item["position_m"]),
        site_position_m=_point(item["site_position_m"]),
    )
    if item["distance_m"] is not None:
        message.distance_m = item["distance_m"]
    if item["track_id"] is not None:
        message.track_id = item["track_id"]
    return message


def response_for(request: pb.DetectRequest, status: pb.DetectResponse.Status, code: str = "",
                 message: str = "") -> pb.DetectResponse:
    """A response that echoes the request's camera, frame and capture time."""
    response = pb.DetectResponse(camera_id=request.camera_id, frame_id=request.frame_id, status=status,
                                 error_code=code, error_message=message)
    if request.HasField("capture_time"):
        response.capture_time.CopyFrom(request.capture_time)
    return response


def result_to_response(result: DetectionResult, request: pb.DetectRequest) -> pb.DetectResponse:
    """An OK response carrying exactly the numbers of the REST answer for the same result."""
    answer = result_to_json(result)
    response = response_for(request, Status.OK)
    response.image.CopyFrom(pb.ImageSize(**answer["image"]))
    response.model.CopyFrom(pb.ModelRef(**answer["model"]))
    response.detections.extend(detection_from_json(item) for item in answer["detections"])
    response.timing_ms.CopyFrom(pb.Timing(**answer["timing_ms"]))
    if "site_note" in answer:
        response.site_note = answer["site_note"]
    return response


def detection_to_json(message: pb.Detection) -> dict[str, Any]:
    box = message.box
    return {
        "score": message.score,
        "box": {"cx": box.cx, "cy": box.cy, "w": box.w, "h": box.h, "angle_deg": box.angle_deg},
        "corners": [[corner.x, corner.y] for corner in message.corners],
        "foot_px": _pair(message, "foot_px"),
        "position_m": _pair(message, "position_m"),
        "distance_m": message.distance_m if message.HasField("distance_m") else None,
        "site_position_m": _pair(message, "site_position_m"),
        "track_id": message.track_id if message.HasField("track_id") else None,
    }


def response_to_json(response: pb.DetectResponse) -> dict[str, Any]:
    """The REST-shaped dict of a response, plus `status` (and the error fields when set)."""
    answer: dict[str, Any] = {
        "camera_id": response.camera_id,
        "frame_id": response.frame_id or None,
        "status": Status.Name(response.status),
    }
    if response.HasField("capture_time"):
        answer["capture_time"] = response.capture_time.ToJsonString()
    if response.error_code or response.error_message:
        answer["error"] = {"code": response.error_code, "message": response.error_message}
    if response.status == Status.OK:
        timing = response.timing_ms
        answer |= {
            "image": {"width": response.image.width, "height": response.image.height},
            "model": {"name": response.model.name, "version": response.model.version},
            "detections": [detection_to_json(item) for item in response.detections],
            "timing_ms": {"decode": timing.decode, "preprocess": timing.preprocess,
                          "inference": timing.inference, "postprocess": timing.postprocess,
                          "total": timing.total},
        }
        if response.site_note:
            answer["site_note"] = response.site_note
    return answer


# ----- cameras and model


def camera_to_message(camera: FisheyeCamera) -> pb.Camera:
    record = camera_to_dict(camera)
    message = pb.Camera(
        id=camera.id, altitude_m=camera.altitude_m,
        image_size=pb.ImageSize(width=camera.image_size[0], height=camera.image_size[1]),
        principal_point=pb.Point(x=camera.principal_point[0], y=camera.principal_point[1]),
        focal_px=pb.Point(x=camera.focal_px[0], y=camera.focal_px[1]), kb=list(camera.kb),
    )
    if camera.max_theta_deg is not None:
        message.max_theta_deg = camera.max_theta_deg
    if "site_pose" in record:
        message.site_pose.CopyFrom(pb.SitePose(**record["site_pose"]))
    if camera.site is not None:
        message.site = camera.site
    if camera.tilt_deg is not None:
        message.tilt_deg.CopyFrom(pb.Point(x=camera.tilt_deg[0], y=camera.tilt_deg[1]))
    for polygon in camera.masks_px or []:
        message.masks_px.append(pb.Polygon(points=[pb.Point(x=u, y=v) for u, v in polygon]))
    if camera.max_view_pixels is not None:
        message.max_view_pixels = camera.max_view_pixels
    if camera.second_look_pixels is not None:
        message.second_look_pixels = camera.second_look_pixels
    if camera.longest_person_ratio is not None:
        message.longest_person_ratio = camera.longest_person_ratio
    return message


def message_to_camera(message: pb.Camera) -> FisheyeCamera:
    """A validated camera from its message (fisheye.CalibrationError when invalid)."""
    record: dict[str, Any] = {
        "id": message.id, "altitude_m": message.altitude_m,
        "image_size": [message.image_size.width, message.image_size.height],
        "principal_point": [message.principal_point.x, message.principal_point.y],
        "focal_px": [message.focal_px.x, message.focal_px.y], "kb": list(message.kb),
    }
    if message.HasField("max_theta_deg"):
        record["max_theta_deg"] = message.max_theta_deg
    if message.HasField("site_pose"):
        pose = message.site_pose
        record["site_pose"] = {"x_m": pose.x_m, "y_m": pose.y_m, "yaw_deg": pose.yaw_deg}
    if message.HasField("site"):
        record["site"] = message.site
    if message.HasField("tilt_deg"):
        record["tilt_deg"] = [message.tilt_deg.x, message.tilt_deg.y]
    if message.masks_px:
        record["masks_px"] = [[[point.x, point.y] for point in polygon.points]
                              for polygon in message.masks_px]
    if message.HasField("max_view_pixels"):
        record["max_view_pixels"] = message.max_view_pixels
    if message.HasField("second_look_pixels"):
        record["second_look_pixels"] = message.second_look_pixels
    if message.HasField("longest_person_ratio"):
        record["longest_person_ratio"] = message.longest_person_ratio
    return camera_from_dict(record)


def model_to_message(info: ModelInfo) -> pb.ModelInfo:
    return pb.ModelInfo(
        name=info.name, version=info.version, input_size=info.input_size, trained_on=info.trained_on,
        box_format=info.box_format, default_min_score=info.default_min_score, pad_value=info.pad_value,
        sha256=info.sha256, nms_iou=info.nms_iou,
        view_operating_points={layout: pb.OperatingPoint(min_score=point.min_score, nms_iou=point.nms_iou)
                               for layout, point in info.view_points},
    )


# ----- sites


def occupancy_to_message(occupancy: dict[str, Any]) -> pb.SiteOccupancy:
    """The gRPC form of a site's occupancy answer (`sites.SiteTracker.occupancy`)."""
    message = pb.SiteOccupancy(site=occupancy["site"], count=occupancy["count"])
    if occupancy["time"] is not None:
        message.time = occupancy["time"]
    for person in occupancy["people"]:
        message.people.append(pb.TrackedPerson(
            track_id=person["track_id"], position_m=_point(person["position_m"]),
            velocity_mps=_point(person["velocity_mps"]), cameras=person["cameras"],
            first_seen=person["first_seen"], last_seen=person["last_seen"], dwell_s=person["dwell_s"],
        ))
    for zone, figures in occupancy["zones"].items():
        message.zones[zone].count = figures["count"]
    for line, tally in occupancy["lines"].items():
        message.lines[line].in_count = tally["in"]
        message.lines[line].out_count = tally["out"]
    return message


def occupancy_from_message(message: pb.SiteOccupancy) -> dict[str, Any]:
    """The REST-shaped occupancy dict of a message (what a watching client prints)."""
    return {
        "site": message.site,
        "time": message.time if message.HasField("time") else None,
        "count": message.count,
        "people": [{
            "track_id": person.track_id, "position_m": _pair(person, "position_m"),
            "velocity_mps": _pair(person, "velocity_mps"), "cameras": list(person.cameras),
            "first_seen": person.first_seen, "last_seen": person.last_seen, "dwell_s": dict(person.dwell_s),
        } for person in message.people],
        "zones": {zone: {"count": figures.count} for zone, figures in sorted(message.zones.items())},
        "lines": {line: {"in": tally.in_count, "out": tally.out_count}
                  for line, tally in sorted(message.lines.items())},
    }
