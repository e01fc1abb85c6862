// Box obstacles (scene key domain.obstacles): OBSTACLES axis-aligned boxes the fluid flows around,
// stored in obstacle_box as (min, max) pairs of vec4 (float32, like the parameter block), declared
// by the shader that includes this file. A face that lies on a wall is moved beyond it by the host
// (sphcore.backends.empty_state): nothing slides between box and wall. Mirror: sphcore/sph/obstacles.py
// (same names, same statements).
//
// The boundary is the walls' (cells.glsl): within h of a box's face, a particle also sees every
// particle mirrored across that face (free-slip ghost fluid, Takeda et al. 1994), so the fluid
// feels the box before it touches it, with the density and pressure of a whole kernel support
// (a repulsive force alone would leave the particles at the face short of neighbours, and their
// pressure, which the sensors on the box read, near zero); integrate.comp puts a particle that
// ended a step inside a box back onto its nearest face. A face's mirror plane runs on beyond the
// box's edge, through the fluid: an image that lands there would double fluid that is really there
// (and the Tait pressure, ~ rho^7, would fling the particle), so only images in the solid count
// (`solid`); near an edge a particle has fewer images, as at a free surface.

#include "real.glsl"

// Faces of the obstacles as mirror planes (cells.glsl: near_walls gave `mirrored` and `wall`): on
// each axis where x lies in front of a face (outside the box on that axis by less than h, within
// it on the others) nearer than that axis's mirrored wall, the face becomes the axis's mirror
// plane. Returns the new bits; `inward` (+1 or -1 per axis) points from each axis's plane into the
// fluid: a particle on a plane coincides with its own image there and is pushed that way.
uint near_obstacles(real3 x, uint mirrored, inout real3 wall, out real3 inward) {
    inward = real3(wall.x == P.box_min.x ? 1.0 : -1.0, wall.y == P.box_min.y ? 1.0 : -1.0,
                   wall.z == P.box_min.z ? 1.0 : -1.0);
    for (uint o = 0u; o < OBSTACLES; ++o) {
        real3 lo = real3(obstacle_box[2u * o].xyz);
        real3 hi = real3(obstacle_box[2u * o + 1u].xyz);
        real3 gap = max(lo - x, x - hi);  // > 0: outside the box on that axis, by that much
        if (DIM == 2u) gap.z = real(0.0);
        if (gap.x >= real(0.0) && gap.x < P.h && gap.y <= real(0.0) && gap.z <= real(0.0)
            && ((mirrored & 1u) == 0u || gap.x < abs(x.x - wall.x))) {
            wall.x = x.x <= lo.x ? lo.x : hi.x;
            inward.x = x.x <= lo.x ? real(-1.0) : real(1.0);
            mirrored |= 1u;
        }
        if (gap.y >= real(0.0) && gap.y < P.h && gap.x <= real(0.0) && gap.z <= real(0.0)
            && ((mirrored & 2u) == 0u || gap.y < abs(x.y - wall.y))) {
            wall.y = x.y <= lo.y ? lo.y : hi.y;
            inward.y = x.y <= lo.y ? real(-1.0) : real(1.0);
            mirrored |= 2u;
        }
        if (DIM == 3u && gap.z >= real(0.0) && gap.z < P.h && gap.x <= real(0.0) && gap.y <= real(0.0)
            && ((mirrored & 4u) == 0u || gap.z < abs(x.z - wall.z))) {
            wall.z = x.z <= lo.z ? lo.z : hi.z;
            inward.z = x.z <= lo.z ? real(-1.0) : real(1.0);
            mirrored |= 4u;
        }
    }
    return mirrored;
}

// The planes i's images are mirrored across (compute_density, walk.glsl): the walls within h of xi (cells.glsl:
// near_walls; reused lists, LIST_SKIN: within list_reach of x_built, where i was at the list's build), then the
// obstacles' faces where nearer (near_obstacles). Returns the bits of `mirrored`; `wall` and `inward` as there.
// Needs cells.glsl included before this file.
uint mirror_planes(real3 x_built, real3 xi, out real3 wall, out real3 inward) {
    uint mirrored = LIST_SKIN > 0u ? near_walls_within(x_built, list_reach(), wall) : near_walls(xi, wall);
    return near_obstacles(xi, mirrored, wall, inward);
}

// Whether an image at y lies in the solid: on or beyond a wall, or in or on an obstacle.
bool solid(real3 y) {
    if (y.x <= P.box_min.x || y.x >= P.box_max.x || y.y <= P.box_min.y || y.y >= P.box_max.y
        || (DIM == 3u && (y.z <= P.box_min.z || y.z >= P.box_max.z))) return true;
    for (uint o = 0u; o < OBSTACLES; ++o) {
        real3 lo = real3(obstacle_box[2u * o].xyz);
        real3 hi = real3(obstacle_box[2u * o + 1u].xyz);
        if (y.x >= lo.x && y.x <= hi.x && y.y >= lo.y && y.y <= hi.y && (DIM == 2u || (y.z >= lo.z && y.z <= hi.z)))
            return true;
    }
    return false;
}
