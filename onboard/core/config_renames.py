"""Renamed configuration keys: the one table of old key -> new key.

A configuration file that still uses an old key is an error naming the new one, never
silently accepted and never reported as a mere unknown key:

    my.toml: pipelines.aie.nis_gate: renamed to pipelines.aie.gate_nis

:func:`onboard.core.config.from_dict` looks for old keys (:func:`renamed_key`) before it
decodes a table, so the check covers every file of a stacked ``--config`` on its own, a
bundled config, and the web page's editor. The configuration a service recording carries
in its meta record was written by the program, not by a person: :func:`migrate` moves its
old keys to their new places, so a recording made before a rename replays with the numbers
it ran with (:func:`onboard.service.recorder.recording_config`).

The naming rule behind the renames is at the top of :mod:`onboard.core.pipeline_config`
(README, "Configuration").
"""

from __future__ import annotations

import copy
from typing import Any, Mapping

SURGE_HEADING_RENAMES = {
    "nis_gate": "gate_nis",
    "gnss_std_m": "gnss_position_std_m",
}
"""``[pipelines.aie]`` and ``[pipelines.kf]`` (issue 31): one word for a gate, a one-sigma
named by its quantity."""

CURRENT_RENAMES = {
    "current_walk": "current_walk_mps_rts",
    "accel_std": "accel_std_mps2",
    "max_speed_through_water": "max_speed_through_water_mps",
    "prior_accel_std": "prior_accel_std_mps2",
    "init_current_std": "initial_current_std_mps",
    "identify_max_current_std": "identify_max_current_std_mps",
    "identify_min_rate": "identify_min_rate_rps",
    "identify_min_speed": "identify_min_speed_mps",
    "gnss_velocity_std": "gnss_velocity_std_mps",
    "dvl_velocity_std": "dvl_velocity_std_mps",
    "unknown_above_std": "unknown_above_std_mps",
    "gain_file": "hgo.gain_file",
    "gamma": "hgo.gamma",
    "gamma_0": "hgo.gamma_0",
    "rho": "hgo.rho",
    "gamma_max": "hgo.gamma_max",
    "hgo_identify": "hgo.identify",
    "hgo_rls_noise_std": "hgo.rls_noise_std_mps2",
    "flow_pitch": "flow.pitch",
    "flow_poles": "flow.poles",
}
"""``[pipelines.current]`` (issue 31): units as suffixes, the high-gain observer's and the
flow observer's keys in their own tables."""

GLIDER_RENAMES = {
    "density": "water_density_kgm3",
    "vertical_water_std": "vertical_water_std_mps",
    "glide_angle_std": "glide_angle_std_rad",
    "min_glide_angle": "min_glide_angle_rad",
}
"""``[pipelines.current.glider]`` (issue 31): units as suffixes; the density is named as
``[sensors.depth] water_density_kgm3``."""

ESESO_RENAMES = {
    "mass_kg": "vehicle.mass_kg",
    "added_mass": "vehicle.added_mass_kg",
    "damping_linear": "vehicle.damping_linear",
    "damping_quadratic": "vehicle.damping_quadratic",
    "cg_z_m": "vehicle.cg_z_m",
    "weight_n": "vehicle.weight_n",
    "buoyancy_n": "vehicle.buoyancy_n",
    "force_allocation": "thrusters.allocation",
    "thruster_max_forward_n": "thrusters.max_forward_n",
    "thruster_max_reverse_n": "thrusters.max_reverse_n",
    "thruster_exponent": "thrusters.exponent",
    "thruster_deadband": "thrusters.deadband",
    "command_timeout_s": "thrusters.command_timeout_s",
    "disturbance_model": "process.disturbance_model",
    "accel_bias_walk": "process.accel_bias_walk_mps2_rts",
    "gyro_bias_walk": "process.gyro_bias_walk_rps_rts",
    "gravity_walk": "process.gravity_walk_mps2_rts",
    "disturbance_walk": "process.disturbance_walk_n_rts",
    "position_walk": "process.position_walk_m_rts",
    "damping_rel_std": "process.damping_rel_std",
    "thrust_rel_std": "process.thrust_rel_std",
    "ins_velocity_std_mps": "noise.ins_velocity_std_mps",
    "ins_bias_std_mps": "noise.ins_bias_std_mps",
    "ins_bias_tau_s": "noise.ins_bias_tau_s",
    "gnss_position_std_m": "noise.gnss_position_std_m",
    "gnss_velocity_std_mps": "noise.gnss_velocity_std_mps",
    "depth_std_m": "noise.depth_std_m",
    "dvl_velocity_std_mps": "noise.dvl_velocity_std_mps",
    "attitude_std_rad": "noise.attitude_std_rad",
    "attitude_yaw_std_rad": "noise.attitude_yaw_std_rad",
    "heading_std_rad": "noise.heading_std_rad",
    "thrust_std_n": "noise.thrust_std_n",
    "accel_std_mps2": "noise.accel_std_mps2",
    "gyro_std_rps": "noise.gyro_std_rps",
    "noise_adapt_updates": "noise.adapt_updates",
    "noise_scale_max": "noise.scale_max",
    "thrust_noise_scale_max": "noise.thrust_scale_max",
    "initial_north_m": "initial.north_m",
    "initial_east_m": "initial.east_m",
    "gravity_mps2": "initial.gravity_mps2",
    "initial_position_std_m": "initial.position_std_m",
    "initial_velocity_std_mps": "initial.velocity_std_mps",
    "initial_attitude_std_rad": "initial.attitude_std_rad",
    "initial_accel_bias_std": "initial.accel_bias_std_mps2",
    "initial_gyro_bias_std": "initial.gyro_bias_std_rps",
    "initial_gravity_std": "initial.gravity_std_mps2",
    "initial_disturbance_std_n": "initial.disturbance_std_n",
}
"""``[pipelines.eseso]`` (issue 31): the flat keys grouped into ``vehicle``,
``thrusters``, ``process``, ``noise`` and ``initial``, random walks with their unit."""

KF_SPLIT_RENAMES = {
    "pipelines.aie.surge.kf_v_d": "pipelines.kf.surge.v_d",
    "pipelines.aie.surge.kf_bias_q": "pipelines.kf.surge.bias_q",
    "pipelines.aie.heading.kf_v_d": "pipelines.kf.heading.v_d",
    "pipelines.aie.heading.kf_bias_q": "pipelines.kf.heading.bias_q",
    "pipelines.diagnose": "diagnose",
}
"""Issue 21: the KF baseline's own table, ``[diagnose]`` at the top level."""


def _in(table: str, renames: Mapping[str, str]) -> dict[str, str]:
    """``renames`` of keys of ``table`` as whole dotted keys."""
    return {f"{table}.{old}": f"{table}.{new}" for old, new in renames.items()}


RENAMED: dict[str, str] = {
    **_in("pipelines.aie", SURGE_HEADING_RENAMES),
    **_in("pipelines.kf", SURGE_HEADING_RENAMES),
    **_in("pipelines.current", CURRENT_RENAMES),
    **_in("pipelines.current.glider", GLIDER_RENAMES),
    **_in("pipelines.eseso", ESESO_RENAMES),
    **KF_SPLIT_RENAMES,
}
"""Old dotted key (or table) -> its new dotted key, as spelled in files."""


def renamed_key(data: Mapping[str, Any], prefix: str = "") -> tuple[str, str] | None:
    """The first old key of :data:`RENAMED` in the tables of ``data`` (a configuration
    file's), in the file's order, with its new name; None when there is none."""
    for key, value in data.items():
        dotted = f"{prefix}.{key}" if prefix else key
        if dotted in RENAMED:
            return dotted, RENAMED[dotted]
        if isinstance(value, Mapping):
            found = renamed_key(value, dotted)
            if found is not None:
                return found
    return None


def migrate(data: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of ``data`` with every old key of :data:`RENAMED` moved to its new place
    (a table renamed whole moves whole). A value already at the new place wins over the
    old key's."""
    out = copy.deepcopy(dict(data))
    while (found := renamed_key(out)) is not None:
        old, new = found
        *old_path, old_key = old.split(".")
        value = _table(out, old_path).pop(old_key)
        *new_path, new_key = new.split(".")
        _table(out, new_path, create=True).setdefault(new_key, value)
    return out


def _table(data: dict[str, Any], path: list[str], create: bool = False) -> dict[str, Any]:
    """The table at ``path`` in ``data`` (made, empty, where missing with ``create``)."""
    for part in path:
        data = data.setdefault(part, {}) if create else data[part]
    return data
