// Parameter block of the marching-cubes shaders (and of sample_field, which also reads the
// particles' neighbour grid): one push-constant range, read as `P.name`. sphcore/params.py
// parses it into a numpy record dtype (MC_PARAMS_DTYPE), the `params` argument of the mirrors.
// Samples are indexed (x, y, z) = numpy axes (0, 1, 2) of the volume, z fastest.
layout(push_constant) uniform Params {
    uvec3 dim;            // samples per axis (cubes per axis: dim - 1)
    uint cube_total;      // cubes: (dim.x - 1) (dim.y - 1) (dim.z - 1)
    vec3 origin;          // position of sample (0, 0, 0) [m]
    float isolevel;       // the surface is value == isolevel; a sample is inside where value > isolevel
    vec3 spacing;         // distance between samples per axis [m]
    uint level;           // HistoPyramid level a reduce_cubes dispatch writes (1 = first above the base)
    vec3 box_min;         // sample_field: origin of the particles' neighbour grid (shaders/sph/params.glsl)
    uint levels;          // HistoPyramid levels above the base (the last one holds one node: the total)
    vec3 box_max;         // sample_field: the walls
    float inv_cell;       // sample_field: 1 / cell size of the neighbour grid
    uvec3 grid_dim;       // sample_field: cells per axis
    uint cell_total;      // sample_field: cells in the neighbour grid
    uint n;               // sample_field: particle count
    float h;              // sample_field: smoothing length [m]
    float h2;             // sample_field: h^2
    float density_coef;   // sample_field: m times W_poly6's coefficient
    uint capacity;        // vertices the output buffers hold; more are counted, not written
} P;
