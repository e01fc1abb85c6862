// Time integrators, chosen by the specialization constant VERLET (scene key time.integrator). The
// step n -> n + 1 is dt = dt_n long (P.dt, or time_state's with ADAPTIVE_DT: choose_dt.comp) and
// a_n = a(x_n, v_n) is compute_forces' acceleration, one force evaluation per step in both:
//   VERLET false, "symplectic_euler" (semi-implicit Euler; Hairer, Lubich & Wanner 2006, sec. VI.3):
//     v_{n+1} = v_n + dt a_n, x_{n+1} = x_n + dt v_{n+1}. Stored: x_{n+1} and v_{n+1} (particle_v).
//     First order: with a constant dt its positions are the leapfrog's, but its stored velocity, the
//     one the viscosity, the outputs and the energy see, is half a step ahead of its positions.
//   VERLET true, "verlet": the leapfrog in kick-drift-kick form (velocity Verlet: Verlet 1967;
//     Swope et al. 1982), the closing kick of the last step done at the start of this one, where
//     a_n is known:
//       v_n       = v_{n-1/2} + dt_{n-1} / 2 a_n      (the first step, dt_{n-1} = 0: the stored v_0)
//       v_{n+1/2} = v_n + dt_n / 2 a_n,  x_{n+1} = x_n + dt_n v_{n+1/2}
//       v*_{n+1}  = v_{n+1/2} + dt_n / 2 a_n           (the end velocity, predicted with a_n)
//     Stored: x_{n+1}, v_{n+1/2} (particle_vh) and v*_{n+1} (particle_v): the next step's forces,
//     the outputs and the energy see v*_{n+1}, which differs from the KDK's v_{n+1} by
//     dt_n / 2 (a_n - a_{n+1}) = O(dt^2). Positions x_n and velocities v_n are second order in dt, also
//     with a varying dt (each step's two half kicks use its own dt) and with velocity-dependent forces
//     (their velocity's error is O(dt^2)); with forces of the positions alone it is exactly the KDK leapfrog.
// Mirror: sphcore/sph/integrators.py (same names, same statements).

#include "real.glsl"

// Symplectic Euler's velocity over the step: v_{n+1} = v_n + dt a_n.
real3 symplectic_euler_kick(real3 v, real3 a, float dt) {
    return v + dt * a;
}

// Verlet's velocity over the step, v_{n+1/2}: the last step's closing half kick (none at the first
// step, dt_prev = 0), then this step's opening one. `vh` is the last step's v_{n-1/2}, `v` the stored v_0.
real3 verlet_kick(real3 v, real3 vh, real3 a, float dt, float dt_prev) {
    real3 vn = v;
    if (dt_prev > 0.0) vn = vh + (0.5 * dt_prev) * a;
    return vn + (0.5 * dt) * a;
}

// The velocity that moves the particle over the step (x_{n+1} = x_n + dt drift_velocity).
real3 drift_velocity(real3 v, real3 vh, real3 a, float dt, float dt_prev) {
    if (VERLET) return verlet_kick(v, vh, a, dt, dt_prev);
    return symplectic_euler_kick(v, a, dt);
}

// The velocity stored in particle_v at the step's end, from the drift velocity v (after the walls).
real3 stored_velocity(real3 v, real3 a, float dt) {
    if (VERLET) return v + (0.5 * dt) * a;
    return v;
}
