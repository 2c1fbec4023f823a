"""
The simulated CBHA as a valve driver sees it: commands in, measured pressures and tip out (no ROS).

:class:`SimulatedArm` joins the valve line (:class:`cbha_inverse.sim.valves.ValveLine`: transport
latency, first-order valves), the quasi-static plant (:class:`cbha_inverse.sim.plant.StaticPlant`)
and the sensors: Gaussian noise on the valve pressures and on the tip, each from a random stream
of its own, so that the tip noise of a seed does not change with the pressure noise. Commands and
measured pressures are in the driver's valve order; the plant works in the scene's actuator order.
``cbha_sim`` runs it on the node clock.
"""

from cbha_inverse.sim.plant import StaticPlant
from cbha_inverse.sim.valves import ValveLine
import numpy as np


class SimulatedArm:
    """
    Valve line, plant and noisy sensors of the simulated arm.

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        The plant's scene (with its model errors).
    order : (m,) int array_like
        ``order[k]``: the scene actuator of valve ``k``
        (:func:`cbha_inverse.robot.safety.valve_order`).
    latency : float  [s]
        Transport delay from a command to the valves.
    valve_time_constant : float  [s]
        First-order valve response.
    tip_noise : float  [m]
        Standard deviation of the measured tip per axis.
    pressure_noise : float  [Pa]
        Standard deviation of each measured valve pressure.
    seed : int
        Seed of the tip noise; the pressure noise draws from its child stream
        ``SeedSequence(seed, spawn_key=(1,))``.
    tolerance : float  [N, N*m]
        Equilibrium residual tolerance of the plant.
    max_iterations : int
        Newton iterations per plant update at most.
    contact_stiffness : float  [N/m]
        Penalty stiffness of the plant's contacts with obstacles
        (:class:`cbha_inverse.sim.plant.StaticPlant`).
    command_kind : str
        ``'tension'`` (commands in N or Pa) or ``'displacement'`` (tendon drives' positions in
        m, lagged by the same line: a drive's position loop), as
        :class:`cbha_inverse.sim.plant.StaticPlant`.

    """

    def __init__(self, scene, order, *, latency, valve_time_constant, tip_noise=0.0,
                 pressure_noise=0.0, seed=0, tolerance=1e-6, max_iterations=20,
                 contact_stiffness=1.0e4, command_kind='tension'):
        self.order = np.asarray(order, dtype=int)
        self.plant = StaticPlant(scene, tolerance=tolerance, max_iterations=max_iterations,
                                 contact_stiffness=contact_stiffness, command_kind=command_kind)
        self.valves = ValveLine(self.order.size, latency, valve_time_constant)
        self.tip_noise = float(tip_noise)
        self.pressure_noise = float(pressure_noise)
        self._tip_rng = np.random.default_rng(seed)
        self._pressure_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(1,)))

    def reset(self):
        """Plant at rest, valves vented, commands in transit dropped (noise streams go on)."""
        self.plant.reset()
        self.valves.reset()

    @property
    def pressures(self):
        """(m,) ndarray [Pa]: the valve pressures at the last :meth:`advance`, scene order."""
        return self.valves.pressures

    def send(self, time, command):
        """
        Send a command; it reaches the valves ``latency`` seconds later.

        Parameters
        ----------
        time : float  [s]
            When it is sent.
        command : (m,) array_like  [Pa]
            Valve set-points in valve order (checked by the caller).

        """
        in_scene_order = np.empty(self.order.size)
        in_scene_order[self.order] = command
        self.valves.send(time, in_scene_order)

    def advance(self, time):
        """
        Move the valves to ``time`` and return their measured pressures.

        Parameters
        ----------
        time : float  [s]
            The new time (a clock that jumps back is a pause).

        Returns
        -------
        (m,) ndarray  [Pa]
            The valve pressures in valve order, with the pressure noise.

        """
        pressures = self.valves.advance(time)
        return pressures[self.order] + self._pressure_rng.normal(
            0.0, self.pressure_noise, self.order.size)

    def update_plant(self):
        """
        Move the plant to the equilibrium of the current (noise-free) valve pressures.

        Returns
        -------
        result : cbha_inverse.core.statics.StaticResult
            The equilibrium (``converged`` False if the budget did not suffice).
        measured_tip : (3,) ndarray  [m]
            The last effector with the tip noise.

        Raises
        ------
        ValueError, ArithmeticError, RuntimeError
            When the static solve fails (the plant keeps its state, no tip noise is drawn).

        """
        result = self.plant.update(self.valves.pressures)
        tip = result.effector_positions[-1]
        return result, tip + self._tip_rng.normal(0.0, self.tip_noise, 3)
