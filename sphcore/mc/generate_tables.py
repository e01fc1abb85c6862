"""Generate the marching-cubes case tables: shaders/mc/tables.glsl and sphcore/mc/tables.py.

Run `python -m sphcore.mc.generate_tables` to (over)write both files.

Conventions (the shaders and their mirrors rely on them):
- Corner k (0..7) of a cube has offset (k & 1, (k >> 1) & 1, (k >> 2) & 1) along axes (0, 1, 2).
- Case index: bit k set <=> corner k is inside <=> its value > level (strictly).
- Edge e = 4 * a + j runs along axis a; with (b, c) the other two axes in increasing order,
  j = ob + 2 * oc, where ob, oc are the edge's offsets along b and c. EDGE_CORNERS[e] is
  (lower, upper): the lower corner has offset 0 along a, upper = lower | (1 << a).
- A face whose two inside corners are diagonal (ambiguous) cuts each inside corner off by its
  own segment. The rule depends on the face's corners only, so neighbouring cubes agree.
- Winding as scikit-image's default (gradient_direction="descent"): a triangle (p, q, r) has
  its right-hand normal (q - p) x (r - p) pointing from outside into the inside (values > level).

Construction of a case: seen from outside the cube, walk each face's corners clockwise; every
run of inside corners is entered through one edge and left through another, and gives the
segment entry -> exit. Each crossed edge then starts one segment and ends another, so the
segments chain into closed loops; each loop becomes a fan of triangles from its first vertex,
chosen so that no fan diagonal joins two edges of one face (see fan_start).
"""
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
GLSL_PATH = ROOT / "shaders" / "mc" / "tables.glsl"
PY_PATH = ROOT / "sphcore" / "mc" / "tables.py"
NO_EDGE = 0xFFFFFFFF  # unused CASE_EDGES entries
WIDTH = 108  # longest line written


def other_axes(a):
    """The two axes other than a, in increasing order."""
    return [axis for axis in range(3) if axis != a]


def edge_corners(e):
    """(lower, upper) corner of edge e."""
    a, j = divmod(e, 4)
    b, c = other_axes(a)
    lower = ((j & 1) << b) | ((j >> 1) << c)
    return lower, lower | (1 << a)


EDGE_CORNERS = [edge_corners(e) for e in range(12)]
EDGE_OF = {frozenset(corners): e for e, corners in enumerate(EDGE_CORNERS)}


def edge_between(k, l):
    """The edge joining corners k and l."""
    return EDGE_OF[frozenset((k, l))]


def face_rings():
    """The six faces, each as its four corners in clockwise order seen from outside the cube."""
    rings = []
    for a in range(3):
        b, c = other_axes(a)
        for side in (0, 1):
            ring = [(side << a) | (ob << b) | (oc << c) for ob, oc in ((0, 0), (1, 0), (1, 1), (0, 1))]
            # the ring turns counter-clockwise about e_b x e_c; the outward normal is (2 side - 1) e_a
            turn = np.cross(np.eye(3)[b], np.eye(3)[c])[a] * (2 * side - 1)
            rings.append(ring[::-1] if turn > 0 else ring)
    return rings


FACE_RINGS = face_rings()
FACE_EDGES = [{edge_between(ring[i - 1], ring[i]) for i in range(4)} for ring in FACE_RINGS]


def face_segments(case, ring):
    """Directed segments (entry edge, exit edge) of one face, one per run of inside corners."""
    inside = [(case >> k) & 1 for k in ring]
    segments = []
    for i in range(4):
        if not inside[i] and inside[(i + 1) % 4]:  # a run starts at ring[i + 1] ...
            j = (i + 1) % 4
            while inside[(j + 1) % 4]:
                j = (j + 1) % 4  # ... and ends at ring[j]
            entry = edge_between(ring[i], ring[(i + 1) % 4])
            exit_ = edge_between(ring[j], ring[(j + 1) % 4])
            segments.append((entry, exit_))
    return segments


def fan_start(loop):
    """The loop's lowest edge on no face that the loop crosses twice (all four of whose edges it
    holds). A fan from there has no diagonal joining two edges of one face: such a diagonal could
    be drawn by the neighbouring cube too, giving a mesh edge four triangles."""
    twice = set().union(*(edges for edges in FACE_EDGES if edges <= set(loop)))
    return min(e for e in loop if e not in twice)


def case_triangles(case):
    """Triangles of a case as triples of edges, loop by loop, each loop fanned from fan_start."""
    following = dict(segment for ring in FACE_RINGS for segment in face_segments(case, ring))
    triangles = []
    while following:
        start = min(following)
        loop = [start]
        edge = following.pop(start)
        while edge != start:
            loop.append(edge)
            edge = following.pop(edge)
        first = loop.index(fan_start(loop))
        loop = loop[first:] + loop[:first]
        triangles += [(loop[0], loop[i], loop[i + 1]) for i in range(1, len(loop) - 1)]
    return triangles


def tables():
    """CASE_VERTICES, CASE_EDGES (a row of CASE_WIDTH per case), CASE_WIDTH, EDGE_CORNERS, EDGE_AXIS."""
    cases = [case_triangles(case) for case in range(256)]
    width = 3 * max(len(triangles) for triangles in cases)
    case_edges = []
    for triangles in cases:
        edges = [e for triangle in triangles for e in triangle]
        case_edges.append(edges + [NO_EDGE] * (width - len(edges)))
    return {
        "CASE_VERTICES": [3 * len(triangles) for triangles in cases],
        "CASE_EDGES": case_edges,
        "CASE_WIDTH": width,
        "EDGE_CORNERS": EDGE_CORNERS,
        "EDGE_AXIS": [e // 4 for e in range(12)],
    }


HEADER = [
    "Marching-cubes case tables. GENERATED by `python -m sphcore.mc.generate_tables`: do not edit.",
    "Conventions: see sphcore/mc/generate_tables.py. In short: corner k has offset",
    "(k & 1, (k >> 1) & 1, (k >> 2) & 1); a case has bit k set where corner k is inside (value > level);",
    "edge e = 4 * axis + j, EDGE_CORNERS[e] = (lower corner, upper corner). Vertex i < CASE_VERTICES[case]",
    "of a case lies on edge CASE_EDGES[case][i] (GLSL: case_edges[case * CASE_WIDTH + i]); each three make",
    "a triangle whose right-hand normal points into the inside (scikit-image's default winding).",
    "Unused entries are NO_EDGE = 0xFFFFFFFF.",
]
GLSL_NOTE = [
    "CASE_VERTICES and CASE_EDGES reach the shaders as the storage buffers case_vertices and case_edges,",
    "filled from sphcore/mc/tables.py: a constant array indexed at run time is copied into every",
    "invocation's registers or stack (lavapipe ran emit_vertices with a constant CASE_EDGES for minutes).",
]


def wrap(items, indent, more=None):
    """`items` separated by commas (one after the last too) in lines of at most WIDTH characters;
    the first line starts with `indent`, the others with `more` (default: `indent`)."""
    lines, line = [], indent
    for item in items:
        if line.strip() and len(line) + len(item) + 1 > WIDTH:
            lines.append(line.rstrip())
            line = more or indent
        line += item + ", "
    return lines + [line.rstrip()]


def array_body(rows, indent="    ", more=None):
    """Lines of an array constructor's arguments: each row starts a line; no comma at the end."""
    lines = [line for row in rows for line in wrap(row, indent, more)]
    lines[-1] = lines[-1].rstrip(",")
    return lines


def sixteens(values):
    return [values[i:i + 16] for i in range(0, len(values), 16)]


def glsl_source(t):
    def uint(n):
        return "NO_EDGE" if n == NO_EDGE else f"{n}u"

    lines = [f"// {line}" for line in HEADER + GLSL_NOTE] + [
        "",
        "const uint NO_EDGE = 0xFFFFFFFFu;",
        f"const uint CASE_WIDTH = {t['CASE_WIDTH']}u;",
        "",
        "const uvec2 EDGE_CORNERS[12] = uvec2[](",
    ]
    lines += array_body([[f"uvec2({lower}u, {upper}u)" for lower, upper in t["EDGE_CORNERS"]]])
    lines += [");", "", f"const uint EDGE_AXIS[12] = uint[]({', '.join(uint(a) for a in t['EDGE_AXIS'])});"]
    return "\n".join(lines) + "\n"


def python_source(t):
    def bracketed(row):
        items = ["NO_EDGE" if n == NO_EDGE else str(n) for n in row]
        items[0], items[-1] = "[" + items[0], items[-1] + "]"
        return items

    lines = ['"""' + HEADER[0]] + HEADER[1:] + [
        '"""',
        "import numpy as np",
        "",
        "NO_EDGE = 0xFFFFFFFF",
        f"CASE_WIDTH = {t['CASE_WIDTH']}",
        "",
        "CASE_VERTICES = np.array([",
    ]
    lines += array_body([[str(n) for n in row] for row in sixteens(t["CASE_VERTICES"])])
    lines += ["], dtype=np.uint32)", "", "CASE_EDGES = np.array(["]
    lines += array_body([bracketed(row) for row in t["CASE_EDGES"]], more="     ")
    lines += ["], dtype=np.uint32)", "", "EDGE_CORNERS = np.array(["]
    lines += array_body([[f"[{lower}, {upper}]" for lower, upper in t["EDGE_CORNERS"]]])
    lines += ["], dtype=np.uint32)", "", f"EDGE_AXIS = np.array({t['EDGE_AXIS']}, dtype=np.uint32)"]
    return "\n".join(lines) + "\n"


def sources():
    """{path: text} of the generated files."""
    t = tables()
    return {GLSL_PATH: glsl_source(t), PY_PATH: python_source(t)}


def main():
    for path, text in sources().items():
        path.write_text(text)
        print(f"wrote {path.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
