// The cells the grid's cell stages take (params.glsl: P.cells_first .. cells_end - 1, a rank's; cells_end 0: every
// cell): invocation k of such a stage takes cell grid_first() + k (backends.dispatch_size dispatches the range).
// Mirror: sphcore/sph/grid_range.py (same names, same statements).

uint grid_first() { return P.cells_end > 0u ? P.cells_first : 0u; }

uint grid_end() { return P.cells_end > 0u ? P.cells_end : P.cell_total; }
