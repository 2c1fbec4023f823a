"""
Pinhole camera model as ROS describes it (``sensor_msgs/CameraInfo``) and its YAML file format.

A :class:`CameraModel` holds the CameraInfo fields: image size, ``distortion_model``
(``plumb_bob``: 5 coefficients k1 k2 p1 p2 k3; ``rational_polynomial``: 8, k1 k2 p1 p2 k3 k4 k5
k6), ``D``, the raw intrinsics ``K`` (3x3), the rectification rotation ``R`` (3x3: raw camera
frame -> rectified frame) and the projection ``P`` (3x4) of the rectified image; for the second
camera of a stereo pair ``P[0, 3] = Tx = -fx' * B`` (B the baseline [m]), so ``P`` projects points
given in the *first* camera's rectified frame, exactly as in ROS.

Files use the camera_calibration_parsers YAML layout (``image_width``, ``image_height``,
``camera_name``, ``camera_matrix``, ``distortion_model``, ``distortion_coefficients``,
``rectification_matrix``, ``projection_matrix``; matrices as ``{rows, cols, data}``), so the
files written by the ROS ``camera_calibration`` tool load unchanged. No OpenCV here.
"""

from dataclasses import dataclass
from pathlib import Path

from cbha_inverse.config_files import check_keys, parse_yaml, read_text
from cbha_inverse.errors import ConfigError
import numpy as np
import yaml

DISTORTION_SIZES = {'plumb_bob': 5, 'rational_polynomial': 8}
"""Number of distortion coefficients of each supported ``distortion_model``."""

YAML_KEYS = {'size': 'image_width', 'distortion_model': 'distortion_model',
             'D': 'distortion_coefficients', 'K': 'camera_matrix', 'R': 'rectification_matrix',
             'P': 'projection_matrix'}
"""The camera_calibration_parsers key of each CameraInfo field."""


class CameraFieldError(ValueError):
    """
    A CameraInfo field is invalid.

    Parameters
    ----------
    field : str
        ``size``, ``distortion_model``, ``D``, ``K``, ``R`` or ``P``.
    problem : str
        What is wrong.

    """

    def __init__(self, field, problem):
        self.field = field
        super().__init__(f'{field}: {problem}')
        self.problem = problem


@dataclass(frozen=True)
class CameraModel:
    """
    One calibrated camera, the fields of ``sensor_msgs/CameraInfo``.

    Attributes
    ----------
    width, height : int  [px]
        Image size.
    distortion_model : str
        ``plumb_bob`` or ``rational_polynomial``.
    distortion : (5,) or (8,) ndarray
        ``D``, OpenCV's coefficient order.
    camera_matrix : (3, 3) ndarray  [px]
        ``K`` of the raw (distorted) image.
    rectification : (3, 3) ndarray
        ``R``: rotation from the raw camera frame to the rectified frame.
    projection : (3, 4) ndarray  [px, px*m]
        ``P`` of the rectified image (fourth column: ``Tx, Ty, 0``).
    name : str
        ``camera_name``.

    """

    width: int
    height: int
    distortion_model: str
    distortion: np.ndarray
    camera_matrix: np.ndarray
    rectification: np.ndarray
    projection: np.ndarray
    name: str = 'camera'

    @property
    def baseline_offset(self):
        """Return ``-Tx / fx'`` [m], the camera's offset along the rectified x axis."""
        return -float(self.projection[0, 3]) / float(self.projection[0, 0])


def camera_model(width, height, distortion_model, distortion, camera_matrix, rectification,
                 projection, name='camera'):
    """
    Build and validate a :class:`CameraModel` from CameraInfo-like fields.

    Parameters
    ----------
    width, height : int  [px]
        Image size (positive).
    distortion_model : str
        ``plumb_bob`` or ``rational_polynomial``.
    distortion : (5,) or (8,) array_like
        ``D``; its length must match ``distortion_model``.
    camera_matrix : (9,) or (3, 3) array_like  [px]
        ``K`` (row-major when flat).
    rectification : (9,) or (3, 3) array_like
        ``R`` (a rotation).
    projection : (12,) or (3, 4) array_like
        ``P`` (row-major when flat).
    name : str
        Camera name.

    Returns
    -------
    CameraModel
        The validated model (float arrays).

    Raises
    ------
    CameraFieldError
        Naming the field that is wrong (a ``ValueError``).

    """
    try:
        size_ok = int(width) == width > 0 and int(height) == height > 0
    except (TypeError, ValueError):
        size_ok = False
    if not size_ok:
        raise CameraFieldError('size', f'must be positive integers, got {width} x {height}')
    if distortion_model not in DISTORTION_SIZES:
        raise CameraFieldError('distortion_model', f'must be one of '
                               f'{sorted(DISTORTION_SIZES)}, got {distortion_model!r}')
    arrays = {}
    for field, value, shape in (('D', distortion, (DISTORTION_SIZES[distortion_model],)),
                                ('K', camera_matrix, (3, 3)), ('R', rectification, (3, 3)),
                                ('P', projection, (3, 4))):
        try:
            array = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise CameraFieldError(field, f'must be numbers, got {value!r}') from None
        if array.size != int(np.prod(shape)):
            raise CameraFieldError(field, f'must have {int(np.prod(shape))} entries for '
                                   f'{distortion_model}, got {array.size}')
        if not np.all(np.isfinite(array)):
            raise CameraFieldError(field, 'has non-finite entries')
        arrays[field] = array.reshape(shape)
    k_matrix, rotation, p_matrix = arrays['K'], arrays['R'], arrays['P']
    if not (k_matrix[0, 0] > 0.0 and k_matrix[1, 1] > 0.0):
        raise CameraFieldError('K', 'focal lengths K[0,0], K[1,1] must be positive')
    if not (p_matrix[0, 0] > 0.0 and p_matrix[1, 1] > 0.0):
        raise CameraFieldError('P', 'focal lengths P[0,0], P[1,1] must be positive')
    if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6) or np.linalg.det(
            rotation) < 0.0:
        raise CameraFieldError('R', 'must be a rotation matrix')
    return CameraModel(int(width), int(height), distortion_model, arrays['D'], k_matrix,
                       rotation, p_matrix, str(name))


CAMERA_KEYS = ('image_width', 'image_height', 'camera_name', 'camera_matrix', 'distortion_model',
               'distortion_coefficients', 'rectification_matrix', 'projection_matrix')
"""The keys of a camera_calibration_parsers YAML file (:func:`camera_to_yaml` writes them all)."""


def _matrix_entry(rows, cols, array):
    return {'rows': rows, 'cols': cols, 'data': [float(v) for v in np.ravel(array)]}


def camera_to_yaml(camera):
    """
    Return the camera_calibration_parsers YAML text of a camera.

    Parameters
    ----------
    camera : CameraModel
        The camera.

    Returns
    -------
    str
        YAML with the keys and layout of ``camera_calibration_parsers``.

    """
    document = {
        'image_width': camera.width,
        'image_height': camera.height,
        'camera_name': camera.name,
        'camera_matrix': _matrix_entry(3, 3, camera.camera_matrix),
        'distortion_model': camera.distortion_model,
        'distortion_coefficients': _matrix_entry(1, camera.distortion.size, camera.distortion),
        'rectification_matrix': _matrix_entry(3, 3, camera.rectification),
        'projection_matrix': _matrix_entry(3, 4, camera.projection),
    }
    return yaml.safe_dump(document, sort_keys=False, default_flow_style=None)


def save_camera_yaml(path, camera):
    """
    Write a camera to a camera_calibration_parsers YAML file.

    Parameters
    ----------
    path : str or os.PathLike
        File to write (parent folders are created).
    camera : CameraModel
        The camera.

    Returns
    -------
    pathlib.Path
        The path written.

    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(camera_to_yaml(camera))
    return path


def _matrix(path, document, key, rows, cols=None):
    entry = document.get(key)
    if not isinstance(entry, dict) or 'data' not in entry:
        raise ConfigError(path, key, 'missing, or not a mapping with rows, cols and data')
    check_keys(path, entry, ('rows', 'cols', 'data'), key)
    data = entry['data']
    if not isinstance(data, list):
        raise ConfigError(path, f'{key}.data', f'must be a list of numbers, got {data!r}')
    declared = (entry.get('rows'), entry.get('cols'))
    if rows is not None and cols is not None and declared != (rows, cols):
        raise ConfigError(path, key, f'must be {rows}x{cols}, declared '
                          f'{declared[0]}x{declared[1]}')
    if isinstance(declared[0], int) and isinstance(declared[1], int) and (
            declared[0] * declared[1] != len(data)):
        raise ConfigError(path, f'{key}.data', f'has {len(data)} entries, rows x cols = '
                          f'{declared[0] * declared[1]}')
    return data


def camera_from_yaml(text, path='<string>'):
    """
    Parse camera_calibration_parsers YAML text.

    Parameters
    ----------
    text : str
        The YAML document.
    path : str or os.PathLike
        File name used in error messages.

    Returns
    -------
    CameraModel
        The camera.

    Raises
    ------
    ConfigError
        ``<file>: <key>: <problem>`` for unreadable YAML, a missing key or a bad value.

    """
    document = parse_yaml(text, path)
    check_keys(path, document, CAMERA_KEYS)
    for key in ('image_width', 'image_height', 'distortion_model'):
        if key not in document:
            raise ConfigError(path, key, 'missing')
    model = document['distortion_model']
    fields = {
        'distortion': _matrix(path, document, 'distortion_coefficients', 1, None),
        'camera_matrix': _matrix(path, document, 'camera_matrix', 3, 3),
        'rectification': _matrix(path, document, 'rectification_matrix', 3, 3),
        'projection': _matrix(path, document, 'projection_matrix', 3, 4),
    }
    try:
        return camera_model(document['image_width'], document['image_height'], model,
                            name=document.get('camera_name', 'camera'), **fields)
    except CameraFieldError as exc:
        raise ConfigError(path, YAML_KEYS[exc.field], exc.problem) from None


def load_camera_yaml(path):
    """
    Read a camera_calibration_parsers YAML file (as written by ROS ``camera_calibration``).

    Parameters
    ----------
    path : str or os.PathLike
        The file.

    Returns
    -------
    CameraModel
        The camera.

    Raises
    ------
    ConfigError
        If the file cannot be read or is not a valid camera description.

    """
    return camera_from_yaml(read_text(path), path)
