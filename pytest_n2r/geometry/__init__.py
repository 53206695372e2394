"""Camera geometry: intrinsics, poses, transforms τ, projection (see each module's *Convention*)."""

from .align import apply_similarity_to_pose, rotation_angle_deg, umeyama
from .camera import Camera
from .camera_stack import CameraStack
from .conventions import c2w_from_colmap, colmap_from_c2w, opencv_to_opengl, opengl_to_opencv
from .pose import (
    Transform,
    Units,
    check_pose,
    compose,
    euler_from_rotation,
    invert_pose,
    orthonormalize,
    relative_pose,
    rotation_from_euler,
)
from .projection import (
    apply_homography,
    backproject,
    camera_rays,
    inside_image,
    pixel_grid,
    pixels_from_camera,
    plane_homography,
    project,
    rotation_homography,
)

__all__ = [
    "Camera", "CameraStack", "Transform", "Units",
    "rotation_from_euler", "euler_from_rotation", "orthonormalize", "compose", "invert_pose",
    "check_pose", "relative_pose",
    "opengl_to_opencv", "opencv_to_opengl", "c2w_from_colmap", "colmap_from_c2w",
    "pixel_grid", "camera_rays", "project", "pixels_from_camera",
    "inside_image", "backproject", "plane_homography", "rotation_homography",
    "apply_homography", "umeyama", "apply_similarity_to_pose", "rotation_angle_deg",
]
