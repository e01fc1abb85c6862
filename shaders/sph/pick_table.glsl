// The pick's table on a rank of sphcore.parallel (Rank.write_pick): pick_table[0] = (the entries, the rows held);
// entry e (another rank) pick_table[1 + e] = (the layers whose rows that rank may need: first, end; the layers of its
// next slab: first, end). A layer's rows are those the step's sort gave it (layer_start): pick_groups.comp writes each
// entry's in band_rows, pick_rows.comp packs them into two zones of slots, pack_rows.comp finds them there, and
// compute_forces.comp's first pass of a step whose exchange overlaps its second takes them (the rows the pick sends).
// Needs PickTable and LayerStart bound.
// Mirror: sphcore/sph/pick_table.py (same names, same statements).

const uint PICK_ALIGN = 4u;  // rows: 16 bytes of a 4-byte buffer

// The first row the step's sort gave layer `layer` (the rows held past the last layer).
uint row_of(uint layer) {
    return layer < uint(P.grid_dim[DIM - 1u]) ? layer_start[layer] : pick_table[0].y;
}

// Entry e's rows: the first, and how many.
uvec2 entry_rows(uint e) {
    uint first = row_of(pick_table[1u + e].x);
    return uvec2(first, row_of(pick_table[1u + e].y) - first);
}

// The slots of each of an entry's two zones (migrants, halo): its rows rounded up to PICK_ALIGN.
uint zone_of(uint rows) { return (rows + PICK_ALIGN - 1u) / PICK_ALIGN * PICK_ALIGN; }
