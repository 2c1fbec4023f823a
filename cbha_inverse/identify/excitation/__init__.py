"""
Excitation programs for identification: pressure holds joined by linear ramps (no ROS).

- :mod:`~cbha_inverse.identify.excitation.program`: :class:`ExcitationProgram`, the actuation
  of a program as a function of time;
- :mod:`~cbha_inverse.identify.excitation.named`: the named programs of a scene (``bends``,
  ``<section>_bends``, ``extension``, ``all``);
- :mod:`~cbha_inverse.identify.excitation.program_file`: a custom program's holds from YAML;
- :mod:`~cbha_inverse.identify.excitation.builder`: :func:`make_program`, a scene's program
  from a name or a file.
"""

from cbha_inverse.identify.excitation.builder import make_program
from cbha_inverse.identify.excitation.named import (
    bend_holds, EXTENSION_FRACTIONS, extension_holds, named_holds, program_names,
    section_groups)
from cbha_inverse.identify.excitation.program import (
    check_bounds, DEFAULT_HOLD_TIME, DEFAULT_RAMP_TIME, ExcitationProgram, mid_range)
from cbha_inverse.identify.excitation.program_file import (
    is_program_file, read_program_file, resolve_program_file)

__all__ = ['bend_holds', 'check_bounds', 'DEFAULT_HOLD_TIME', 'DEFAULT_RAMP_TIME',
           'ExcitationProgram', 'extension_holds', 'EXTENSION_FRACTIONS', 'is_program_file',
           'make_program', 'mid_range', 'named_holds', 'program_names', 'read_program_file',
           'resolve_program_file', 'section_groups']
