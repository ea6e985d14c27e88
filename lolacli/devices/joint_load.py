"""A joint behind an emulated CiA 402 drive: the drive's :class:`~lolacli.devices.cia402.Load`
that runs seed 000's P-PI-PI cascade on a motor, gear and link
(:class:`lolacli.motion.joint.Cascade`, the one implementation the ``joint`` commands run).

The drive counts position in motor encoder increments: a link radian is
:attr:`~lolacli.motion.joint.JointParams.increments_per_rad` of them. Each bus cycle the
drive's demand becomes the cascade's targets, held over the 0.1 ms control periods until
the next cycle's step (a step first runs the periods since the last one on the targets
held over them, then takes the new demand; a bus period that is not a whole number of
periods carries its rest on):

* position (CSP, profile position): the target position; the target velocity is the
  difference of successive demands over the cycle (× ``kvel_ff`` = 1 + k_e in the
  cascade), the current feed-forward the inverse dynamics of the target (J θ̈d +
  G sin θd) / (N k_t) with θ̈d from successive target velocities. A velocity limit
  (``limit``) limits how fast the target may move, as the kinematic follower does;
* velocity (CSV): the target position integrates the demand velocity;
* stop (quick stop, fault reaction): the target velocity ramps to rest at the
  deceleration (0: at once) and the target position integrates it;
* torque (CST): the demand (‰ of the rated torque, ``limit``: 0x6076 in mN·m, 0 for the
  joint's own :attr:`JointLoad.rated_torque_mnm`) is a link torque; through the link's
  torque per ampere N k_t it becomes the current command itself. The position and
  velocity loops are bypassed, the current PI runs (the command clamped at the current
  limit). Back from torque to another mode, the targets start from the joint as it is.

A drive standing on its demand (actual = demand, velocity 0 in increments) is not
stepped while its outputs stay the same (:meth:`Device.cycle`'s rest cache): the joint
waits there as it is, within an increment of the demand. In torque a joint is never at
rest (:attr:`torque_moves`). The compiled chain core runs the same steps in C on a copy
of this state (``lolacli/emulator/_ccore.c``, ``joint_follow``; the tables:
``lolacli/devices/flat.py``), operation for operation, so both give the same doubles.

When the drive's actual values are not the ones this load gave last (the drive was
disabled, its brake holding the joint, or another load moved it), the joint starts
again at rest at the actual position.
"""

from __future__ import annotations

import math

from lolacli.devices.cia402 import POSITION, TORQUE, VELOCITY, Load
from lolacli.motion.joint import POSITION_PERIOD_NS, Cascade, JointParams


class JointLoad(Load):
    """The joint ``params`` behind a drive (module docstring); ``kvel_ff`` = 1 + k_e."""

    model = "joint"
    torque_moves = True

    def __init__(self, params: JointParams, *, kvel_ff: float = 1.0) -> None:
        self.params = params
        self.scale = params.increments_per_rad
        self.cascade = Cascade(params, kvel_ff=kvel_ff)
        # the current feed-forward's inverse dynamics per A: J / (N k_t), G / (N k_t)
        self.inertia_per_a = params.inertia_kgm2 / params.link_torque_per_a
        self.gravity_per_a = params.gravity_nm / params.link_torque_per_a
        #: the torque 1000 ‰ is when the drive's 0x6076 is 0: the link torque at the
        #: current limit, N k_t I_max, in mN·m
        self.rated_torque_mnm = round(params.link_torque_per_a * params.max_current_a * 1000)
        self.last: tuple[int, int] | None = None  # (position, velocity) given back last
        self.pending_ns = 0  # time short of a whole control period, carried on
        self.ref = 0.0  # target position, rad
        self.ref_v = 0.0  # target velocity, rad/s
        self.ff = 0.0  # current feed-forward, A (in torque: the current command)
        self.torque = False  # the targets held are a torque's (the loops bypassed)

    def follow(
        self, kind: str, demand: int, position: int, velocity: int, limit: int, dt_ns: int
    ) -> tuple[int, int]:
        scale = self.scale
        cascade = self.cascade
        if self.last != (position, velocity):
            cascade.reset(position / scale)
            self.ref, self.ref_v, self.pending_ns = position / scale, velocity / scale, 0
            self.ff = self.gravity_per_a * math.sin(self.ref)
            self.torque = False
        if dt_ns <= 0:
            self.last = (position, velocity)
            return self.last
        # the time since the last step ran on the targets the drive held over it
        periods, self.pending_ns = divmod(self.pending_ns + dt_ns, POSITION_PERIOD_NS)
        ref, ref_v = self.ref, self.ref_v
        if periods:
            cascade.run((ref,) * periods, (ref_v,) * periods, (self.ff,) * periods,
                        current_only=self.torque)
        if kind == TORQUE:  # the current command, held until the next step
            rated = limit or self.rated_torque_mnm
            self.ff = demand * rated / 1e6 / self.params.link_torque_per_a
            self.torque = True
            self.last = (round(cascade.theta * scale), round(cascade.omega * scale))
            return self.last
        if self.torque:  # out of torque: the targets start from the joint as it is
            ref, ref_v = cascade.theta, cascade.omega
            self.torque = False
        # the new demand: the targets until the next step
        dt_s = dt_ns * 1e-9
        if kind == POSITION:
            target = demand / scale
            if limit:
                step = limit * dt_s / scale
                target = max(ref - step, min(ref + step, target))
            v = (target - ref) / dt_s
            ref = target
        elif kind == VELOCITY:
            v = demand / scale
            ref += v * dt_s
        else:  # stop: ramp the target velocity to rest
            step = limit * dt_s / scale if limit else math.inf
            v = max(0.0, abs(ref_v) - step)
            v = v if ref_v > 0 else -v
            ref += v * dt_s
        self.ff = self.inertia_per_a * (v - ref_v) / dt_s + self.gravity_per_a * math.sin(ref)
        self.ref, self.ref_v = ref, v
        self.last = (round(cascade.theta * scale), round(cascade.omega * scale))
        return self.last


__all__ = ["JointLoad"]
