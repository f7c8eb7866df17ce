"""Unit conversion and the viscosity mapping onto Blender's Mantaflow (no bpy).

Everything the engine sees is SI. Blender values are converted here, once.
"""

import math

# 1 Mantaflow time unit is 0.4 s (DESIGN.md, "What Mantaflow does"; measured on Blender 3.4.1).
MANTAFLOW_TIME_UNIT_S = 0.4


class UnitError(ValueError):
    """A field value that cannot be exported (NaN, infinite, negative...)."""


def check_finite(name, value, minimum=None, strictly_positive=False):
    """Return float(value) or raise UnitError with a one-line message naming the field."""
    try:
        value = float(value)
    except (TypeError, ValueError) as exc:
        raise UnitError("%s is not a number: %r" % (name, value)) from exc
    if not math.isfinite(value):
        raise UnitError("%s must be a finite number, got %s" % (name, value))
    if strictly_positive and value <= 0.0:
        raise UnitError("%s must be > 0, got %g" % (name, value))
    if minimum is not None and value < minimum:
        raise UnitError("%s must be >= %g, got %g" % (name, minimum, value))
    return value


def to_metres(value, scale_length):
    """Blender units → metres (scene.unit_settings.scale_length metres per Blender unit)."""
    return float(value) * float(scale_length)


def vec_to_metres(vec, scale_length):
    return [to_metres(c, scale_length) for c in vec]


def kinematic_viscosity(eta, density):
    """ν = η / ρ  [m²/s] from dynamic viscosity η [Pa·s] and density ρ [kg/m³].

    This is the only place the dynamic → kinematic conversion happens.
    """
    eta = check_finite("viscosity", eta, minimum=0.0)
    density = check_finite("density", density, strictly_positive=True)
    return eta / density


def diffusion_base_exponent(nu):
    """(viscosity_base, viscosity_exponent) with base · 10^-exponent = ν, as Blender presets write it.

    Blender's Honey.py uses 2.0 / 3 (2e-3 m²/s). The exponent is an int in [0, 10] and the base a
    float in [0, 10]; values outside that range are clamped to the nearest representable one.
    """
    nu = check_finite("kinematic viscosity", nu, minimum=0.0)
    if nu == 0.0:
        return 0.0, 0
    exponent = -int(math.floor(math.log10(nu)))  # base in [1, 10)
    exponent = min(max(exponent, 0), 10)
    base = nu * 10.0 ** exponent
    return min(base, 10.0), exponent


def variational_viscosity_value(nu, longest_side_m):
    """Mantaflow's `viscosity_value` for kinematic ν [m²/s] in a domain whose longest side is L [m].

    ν = viscosity_value · L² / T, hence viscosity_value = ν · T / L² (domain units), T = MANTAFLOW_TIME_UNIT_S.
    """
    nu = check_finite("kinematic viscosity", nu, minimum=0.0)
    length = check_finite("domain size", longest_side_m, strictly_positive=True)
    return nu * MANTAFLOW_TIME_UNIT_S / (length * length)
