"""A scene's excitation program from a name or a YAML file (:func:`make_program`)."""

from cbha_inverse.identify.excitation.named import named_holds
from cbha_inverse.identify.excitation.program import (
    check_bounds, DEFAULT_HOLD_TIME, DEFAULT_RAMP_TIME, ExcitationProgram)
from cbha_inverse.identify.excitation.program_file import (
    is_program_file, read_program_file, resolve_program_file)


def make_program(scene, program, *, hold_time=DEFAULT_HOLD_TIME, ramp_time=DEFAULT_RAMP_TIME,
                 start=None, end=None, bounds=None):
    """
    Build a named or custom excitation program for a scene.

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        Its ``actuator_names``, ``actuator_sections`` and (without ``bounds``) actuator
        bounds are used.
    program : str or os.PathLike
        A name of :func:`cbha_inverse.identify.excitation.named.program_names` or a YAML file
        of holds (``.yaml``/``.yml``: a path, or relative to the package's ``config/``, e.g.
        ``excitation/cbha_example.yaml``).
    hold_time, ramp_time : float  [s]
        See :class:`cbha_inverse.identify.excitation.program.ExcitationProgram`.
    start, end : (m,) array_like, optional  [Pa]
        Scene order (default mid range).
    bounds : tuple of two (m,) array_like, optional  [Pa]
        ``(lower, upper)``, scene order: the bounds the named programs span and a file's values
        must lie within, e.g. a valve driver's (:func:`cbha_inverse.robot.safety.command_bounds`
        with its ``max_pressure``); default the scene's actuator bounds.

    Returns
    -------
    cbha_inverse.identify.excitation.program.ExcitationProgram

    Raises
    ------
    ValueError
        On an unknown program name, invalid times, start, end or bounds.
    cbha_inverse.errors.ConfigError
        On a bad program file (file and key named).

    """
    lower, upper = check_bounds(*((scene.lower_bounds, scene.upper_bounds) if bounds is None
                                  else bounds))
    if is_program_file(program):
        holds, labels = read_program_file(resolve_program_file(program), scene.actuator_names,
                                          lower, upper)
    else:
        holds, labels = named_holds(str(program), lower, upper, scene.actuator_sections,
                                    scene.actuator_names)
    return ExcitationProgram(holds, lower, upper, hold_time=hold_time, ramp_time=ramp_time,
                             start=start, end=end, labels=labels)
