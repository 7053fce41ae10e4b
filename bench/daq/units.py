"""SI units of logged fields, from the thesis nomenclature the field names follow.

Every imbench log field is named after its thesis symbol, lower-cased (DESIGN.md): ``i_*`` are
currents, ``u_*`` voltages, ``psi_*`` flux linkages, ``omega_*`` electrical angular speeds,
``m_*`` torques, ... One rule table here gives each field its unit, so the MCAP schema text (as
``# [unit]`` comments, which ros2msg parsers skip) and the ``units`` metadata record say it without
every controller declaring it. A name no rule covers gets "" (unitless or unknown).
"""

from __future__ import annotations

__all__ = ["unit_of"]

_EXACT = {
    "t": "s", "tick": "ticks", "enc_count": "counts", "enc_index": "counts", "status": "bits",
    "rho": "rad", "p_in": "W", "u_sat": "", "lpv_active": "",
    "inv_enabled": "", "inv_fault": "", "enable": "", "overrun": "", "tripped": "",
    "l_m": "H", "r_s": "Ω", "r_r": "Ω", "temp_s": "°C", "temp_r": "°C",  # mock plant truth (saturation, thermal)
    "r_s_hat": "Ω", "shaft_counts": "counts",  # standstill identification (bench.workflows.commission)
}  # fmt: skip
# (prefix, unit), first match wins: more specific prefixes first
_PREFIX = (
    ("raw_", "ADC code"),
    ("lpv_delta", ""),  # scheduling parameters, normalised
    ("lpv_i_", "A"),
    ("i_", "A"),
    ("u_", "V"),
    ("psi", "Wb"),
    ("omega", "rad/s"),
    ("theta", "rad"),
    ("m_", "N m"),
)
_SUFFIX = (("_us", "µs"),)


def unit_of(field: str) -> str:
    """SI unit of a logged field by its (thesis) name, e.g. ``i_sd`` -> "A", ``omega_hat`` -> "rad/s"."""
    if field in _EXACT:
        return _EXACT[field]
    for suffix, unit in _SUFFIX:
        if field.endswith(suffix):
            return unit
    for prefix, unit in _PREFIX:
        if field.startswith(prefix):
            return unit
    return ""
