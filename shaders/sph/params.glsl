// Parameter block shared by every SPH shader: one push-constant range, read as `P.name`.
// The numba mirrors read the same bytes: sphcore/params.py parses this block into a numpy
// record dtype (std430 offsets), so the two sides cannot drift. All coefficients are folded
// on the host (sphcore/params.py: fold_parameters); units are SI.
layout(push_constant) uniform Params {
    uint n;               // particle count
    float h;              // smoothing length [m]
    float h2;             // h^2 [m^2]
    float density_coef;   // m * 4 / (pi h^8): rho_i = density_coef * sum_j (h^2 - r^2)^3   [kg/m^2 / m^6]
    float pressure_coef;  // m * 30 / (pi h^5): minus m times the coefficient of grad W_spiky
    float viscosity_coef; // mu * m * 40 / (pi h^5): mu * m * lap W_visc's coefficient
    float rest_density;   // rho_0 [kg/m^2] (2D: mass per unit area)
    float stiffness;      // k in p = k (rho - rho_0) [m^2/s^2]
    float dt;             // time step [s]
    float restitution;    // fraction of the normal speed kept on a wall bounce [-]
    vec2 gravity;         // [m/s^2]
    vec2 box_min;         // walls [m]
    vec2 box_max;         // walls [m]
} P;
