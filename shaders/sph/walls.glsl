// Wall models, chosen by the specialization constant NO_SLIP (scene key domain.wall_model): the
// velocity of a particle's mirror image across the walls and obstacle faces (cells.glsl: near_walls,
// reflected; obstacles.glsl: near_obstacles) of the axes whose bits are set in `image`. Only the
// velocity-dependent terms see it (viscosity.glsl); positions are mirrored the same way in both models.
//   NO_SLIP false, "free_slip" (mirror ghost particles, Libersky et al. 1993): the image's normal
//     velocity is reversed, its tangential velocity kept, so the wall exerts no shear.
//   NO_SLIP true, "no_slip" (Takeda, Miyama & Sekiya 1994; Marrone et al. 2011's mirrored ghost
//     velocities): the image's whole velocity is reversed, so the velocity interpolated at the wall
//     is zero and the viscous term drags the fluid along it.
// Mirror: sphcore/sph/walls.py (same names, same statements).

#include "real.glsl"

// Free slip: the components of the mirrored axes reversed.
real3 free_slip(real3 v, uint image) {
    return real3((image & 1u) != 0u ? -v.x : v.x, (image & 2u) != 0u ? -v.y : v.y, (image & 4u) != 0u ? -v.z : v.z);
}

// No slip: the whole velocity reversed.
real3 no_slip(real3 v) {
    return -v;
}

// Velocity of the image `image` of a particle moving at v (image 0: the particle itself).
real3 image_velocity(real3 v, uint image) {
    if (image == 0u) return v;
    if (NO_SLIP) return no_slip(v);
    return free_slip(v, image);
}
