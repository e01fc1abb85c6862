// The layout of a rank's rows for another rank (sphcore.parallel; pack_rows.comp writes it, place_rows.comp reads
// it): a sender's migrants' runs (position, velocity, density, id, and Verlet's half-step velocity), then its halo's
// (position, velocity, density, id), each run of a buffer's rows from a multiple of 16 bytes (backends.PACK_GRAIN),
// in words (4 bytes; a real is REAL_WORDS of them).
// Mirror: sphcore/sph/packed_rows.py (same names, same statements).

#ifdef SPHCORE_FLOAT64
const uint REAL_WORDS = 2u;
#else
const uint REAL_WORDS = 1u;
#endif

// The words of a run of `rows` rows of `words` words each, from a multiple of 16 bytes (4 words).
uint run_words(uint rows, uint words) { return (rows * words + 3u) / 4u * 4u; }

// The words of the halo's runs of `halo` rows.
uint halo_words(uint halo) {
    return 2u * run_words(halo, 4u * REAL_WORDS) + run_words(halo, REAL_WORDS) + run_words(halo, 1u);
}

// The words of the migrants' runs of `migrants` rows (the halo's, and Verlet's half-step velocity): where the halo's
// start.
uint migrant_words(uint migrants) {
    uint words = halo_words(migrants);
    if (VERLET) words += run_words(migrants, 4u * REAL_WORDS);
    return words;
}
