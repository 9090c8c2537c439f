"""jaxsim's world (JAX, float64): numpy, jax and jaxsim only (``rbcheck repro`` embeds this file as it is).

A body is a ``JaxSimModel`` of its own built from an SDF string (:func:`model_sdf`: one link, its inertial at
the link origin = COM with the full tensor, no collision, no joint: a floating base), stepping with the
variant's integrator ("semi_implicit_euler": ``SemiImplicitEuler``, "rk4": ``RungeKutta4``). Gravity
(0, 0, −g) is jaxsim's scalar g; any other direction goes into the link force (:func:`engine_gravity`). State
in the Mixed velocity representation: ``base_position`` = x_W, ``base_quaternion`` = q_WB (w x y z),
``base_velocity`` = [v_W, ω_W] (world axes): the packed state's own quantities; every step starts from the
packed state (``JaxSimModelData.build``). Forces: ``link_forces`` = [f_W at the COM without the weight jaxsim
applies, τ_W]. A step is :func:`step`; rbcheck's adapter (cross_checks/engines/jaxsim_engine.py) runs it in
the compiled loop of :func:`run_fn`, which :class:`Bodies` calls with a count of 1 per step: the same
computation, step by step. docs/engine_conventions.md, "jaxsim 0.9".
"""
import dataclasses

import jax
import jax.numpy as jnp
import jaxsim.api as js
import numpy as np
from jaxsim import VelRepr

jax.config.update("jax_enable_x64", True)   # jaxsim computes in float64 (process-global)

#: jaxsim's ``IntegratorType`` member of each variant.
INTEGRATORS = {"semi_implicit_euler": "SemiImplicitEuler", "rk4": "RungeKutta4"}
#: Steps of one compiled run call (``lax.fori_loop`` with a traced count: a shorter call costs no more).
CHUNK = 1024
MODEL_NAME = "rbcheck_body"


def engine_gravity(gravity_W) -> float:
    """The scalar gravity (m/s², along −z) given to jaxsim: g for a gravity (0, 0, −g), else 0 (the weight
    then goes into the link force)."""
    g = np.asarray(gravity_W, dtype=float)
    return float(-g[2]) if g[0] == 0.0 and g[1] == 0.0 else 0.0


def model_sdf(mass_kg, inertia_B) -> str:
    """SDF 1.7 of one link named ``body``: an ``<inertial>`` at the link origin with ``mass_kg`` and the full
    tensor ``inertia_B`` (kg m², about the COM, link axes), no ``<collision>``, no joint; every number with
    Python's shortest round-trip repr (exactly the double)."""
    inertia = np.asarray(inertia_B, dtype=float)
    names = (("ixx", 0, 0), ("ixy", 0, 1), ("ixz", 0, 2), ("iyy", 1, 1), ("iyz", 1, 2), ("izz", 2, 2))
    moments = "".join(f"<{n}>{float(inertia[i, j])!r}</{n}>" for n, i, j in names)
    return (
        '<?xml version="1.0"?>\n<sdf version="1.7"><model name="' + MODEL_NAME + '"><link name="body">'
        f"<inertial><pose>0 0 0 0 0 0</pose><mass>{float(mass_kg)!r}</mass><inertia>{moments}</inertia>"
        "</inertial></link></model></sdf>"
    )


def build_model(mass_kg, inertia_B, gravity, variant):
    """The jaxsim model of one free link (:func:`model_sdf`) under the scalar ``gravity`` (m/s², along −z)
    for ``variant``. Its SDF text is not kept (``built_from``, a static field, would make every body's model a
    pytree structure, and a compilation, of its own; the model's numbers are all in its arrays)."""
    model = js.model.JaxSimModel.build_from_model_description(
        model_sdf(mass_kg, inertia_B),
        model_name=MODEL_NAME,
        is_urdf=False,
        time_step=0.001,
        gravity=gravity,
        integrator=getattr(js.model.IntegratorType, INTEGRATORS[variant]),
    )
    return model


def compact(model):
    """``model`` without its SDF text (see :func:`build_model`)."""
    return dataclasses.replace(model, built_from=MODEL_NAME)


def step(model, y, f6, scale, key=None):
    """One jaxsim step of the packed state ``y`` (13,): the velocities scaled by ``scale`` (13,: a pre-step
    decay, ones for none), the link force ``f6`` (6,: [f_W, τ_W]) applied. (``key``: unused here; rbcheck's
    adapter's step with a force callback takes it.)"""
    y = y * scale
    data = js.data.JaxSimModelData.build(
        model=model,
        base_position=y[0:3],
        base_quaternion=y[6:10],
        base_linear_velocity=y[3:6],
        base_angular_velocity=y[10:13],
        velocity_representation=VelRepr.Mixed,
    )
    data = js.model.step(model, data, link_forces=f6[None, :])
    v = data.base_velocity
    return jnp.concatenate([data.base_position, v[0:3], data.base_quaternion, v[3:6]])


def run_fn(step_fn=step):
    """``run(model, dt, y0, count, f6, scale, key)``: ``count`` (≤ CHUNK, traced) steps of ``step_fn`` from
    ``y0`` at ``dt`` (s, traced), in one ``lax.fori_loop``; returns the last state and the CHUNK rows (the
    first ``count`` are the states after each step)."""

    def run(model, dt, y0, count, f6, scale, key):
        model = dataclasses.replace(model, time_step=dt)

        def body(i, carry):
            y, rows = carry
            y = step_fn(model, y, f6, scale, key)
            return y, rows.at[i].set(y)

        return jax.lax.fori_loop(0, count, body, (y0, jnp.zeros((CHUNK, 13))))

    return run


class Bodies:
    """Bodies ``(mass_kg, inertia_B (3, 3), None)``, each its own model, under ``gravity_W``; raw rows packed
    states. A step is the compiled :func:`run_fn` loop run once (a count of 1). A weight jaxsim does not apply
    (gravity off −z) is added to the applied force here; rbcheck's adapter runs such a scenario in a frame
    turned onto jaxsim's z axis instead (jaxsim_engine.jaxsim_frame: a link force is a wrench about the world
    origin held over RK4's stages, first order), so a reproducer refuses it (jaxsim_engine.repro_refuses)."""

    def __init__(self, bodies, gravity_W, variant, dt_s):
        g = engine_gravity(gravity_W)
        self.models = [compact(build_model(m, inertia, g, variant)) for m, inertia, _ in bodies]
        self.extra_W = [float(m) * np.asarray(gravity_W, dtype=float) if g == 0.0 else np.zeros(3)
                        for m, _, _ in bodies]
        self.dt, self.run = np.float64(dt_s), jax.jit(run_fn())
        self.scale, self.key = np.ones(13), np.int64(0)
        self.f6 = [np.zeros(6) for _ in bodies]

    def set_state(self, y):
        self.y = np.array(y, dtype=float)

    def apply(self, f_W, tau_W):
        self.f6 = [np.concatenate([np.asarray(f, dtype=float) + w, np.asarray(t, dtype=float)])
                   for f, t, w in zip(f_W, tau_W, self.extra_W)]

    def step(self):
        self.y = np.array([np.asarray(self.run(m, self.dt, y, np.int64(1), f6, self.scale, self.key)[0])
                           for m, y, f6 in zip(self.models, self.y, self.f6)])

    def read(self):
        return self.y

    def packed(self, raw):
        return np.asarray(raw, dtype=float)


def world(bodies, gravity_W, variant, dt_s):
    return Bodies(bodies, gravity_W, variant, dt_s)
