"""
Conversions between ``sensor_msgs/Image`` / ``CameraInfo`` and numpy / camera models.

No cv_bridge (not on PyPI): pixels are numpy views of the message data.

Images are checked before they are used: an unsupported encoding, a size that differs from the
camera model or a ``data`` field shorter than ``step * height`` gives a :class:`ImageRejected`
with the reason (counted by the tracker), never an exception from numpy.
"""

from cbha_inverse.vision.camera import camera_model
import numpy as np
from sensor_msgs.msg import CameraInfo, Image

ENCODINGS = {'mono8': ('mono', 1), 'bgr8': ('bgr', 3), 'rgb8': ('rgb', 3)}
"""Accepted encodings: the detector's channel order and the channels per pixel."""


class ImageRejected(ValueError):
    """
    An image message cannot be used.

    Parameters
    ----------
    reason : str
        ``encoding``, ``size`` or ``truncated`` (the diagnostics counter).
    detail : str
        What is wrong, for the log.

    """

    def __init__(self, reason, detail):
        super().__init__(detail)
        self.reason = reason


def image_array(message, width=None, height=None):
    """
    Return the pixels of an image message and their channel order.

    Parameters
    ----------
    message : sensor_msgs.msg.Image
        ``mono8``, ``bgr8`` or ``rgb8``.
    width, height : int, optional  [px]
        Expected size (the camera model's).

    Returns
    -------
    pixels : (H, W, 3) or (H, W) ndarray of uint8
        A view of the message data (rows of ``step`` bytes, padding cut).
    order : str
        ``bgr``, ``rgb`` or ``mono``.

    Raises
    ------
    ImageRejected
        For another encoding, an unexpected size or too little data.

    """
    if message.encoding not in ENCODINGS:
        raise ImageRejected('encoding', f'encoding {message.encoding!r} is not one of '
                            f'{sorted(ENCODINGS)}')
    order, channels = ENCODINGS[message.encoding]
    rows, cols, step = int(message.height), int(message.width), int(message.step)
    if (width is not None and cols != width) or (height is not None and rows != height):
        raise ImageRejected('size', f'image {cols}x{rows} does not match the camera model '
                            f'{width}x{height}')
    if rows <= 0 or cols <= 0 or step < cols * channels:
        raise ImageRejected('size', f'image {cols}x{rows} with step {step} is not valid')
    data = np.frombuffer(message.data, dtype=np.uint8)
    if data.size < step * rows:
        raise ImageRejected('truncated', f'{data.size} bytes of data, step x height = '
                            f'{step * rows}')
    pixels = data[:step * rows].reshape(rows, step)[:, :cols * channels]
    return (pixels if channels == 1 else pixels.reshape(rows, cols, channels)), order


def image_message(pixels, encoding, stamp, frame_id):
    """
    Build an image message from pixels.

    Parameters
    ----------
    pixels : (H, W, 3) or (H, W) ndarray of uint8
        Pixels in the encoding's layout.
    encoding : str
        ``mono8``, ``bgr8`` or ``rgb8``.
    stamp : builtin_interfaces.msg.Time
        Header stamp (the exposure time).
    frame_id : str
        Optical frame of the camera.

    Returns
    -------
    sensor_msgs.msg.Image
        The message (``step`` = width x channels, no padding).

    """
    pixels = np.ascontiguousarray(pixels, dtype=np.uint8)
    message = Image()
    message.header.stamp = stamp
    message.header.frame_id = frame_id
    message.height, message.width = int(pixels.shape[0]), int(pixels.shape[1])
    message.encoding = encoding
    message.is_bigendian = 0
    message.step = int(pixels.strides[0])
    message.data = pixels.tobytes()
    return message


def camera_info_message(camera, stamp, frame_id):
    """
    Build the ``CameraInfo`` of a camera model.

    Parameters
    ----------
    camera : CameraModel
        The camera.
    stamp : builtin_interfaces.msg.Time
        Header stamp.
    frame_id : str
        Optical frame of the camera.

    Returns
    -------
    sensor_msgs.msg.CameraInfo
        The message.

    """
    message = CameraInfo()
    message.header.stamp = stamp
    message.header.frame_id = frame_id
    message.width, message.height = camera.width, camera.height
    message.distortion_model = camera.distortion_model
    message.d = [float(v) for v in camera.distortion]
    message.k = [float(v) for v in camera.camera_matrix.ravel()]
    message.r = [float(v) for v in camera.rectification.ravel()]
    message.p = [float(v) for v in camera.projection.ravel()]
    return message


def camera_from_info(message):
    """
    Build a camera model from a ``CameraInfo`` message.

    Parameters
    ----------
    message : sensor_msgs.msg.CameraInfo
        The message.

    Returns
    -------
    CameraModel
        The camera (name = the message's frame_id).

    Raises
    ------
    CameraFieldError
        Naming the field that is wrong (a ``ValueError``).

    """
    return camera_model(message.width, message.height, message.distortion_model,
                        list(message.d), list(message.k), list(message.r), list(message.p),
                        message.header.frame_id or 'camera')
