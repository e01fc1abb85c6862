"""Sphinx directives that draw scenes.md's tables from the code, so the page never drifts from it.

    ```{scene-keys}
    ```
        every key of sphcore.scene.SCHEMA (what `sphcore keys` prints): one table per section, a row
        per key with its default (as `sphcore keys` writes it), unit, range, type and meaning.

    ```{scene-models}
    ```
        the models of physics.model (sphcore.scene.PRESETS): a row per key a model sets, a column per
        model, the default model marked.

    ```{scene-presets}
    ```
        the named model configurations of sphcore.validate.configs.CONFIGS: the keys each sets (as
        TOML values) and the comment beside it in that module.

    ```{shipped-scenes}
    ```
        the scenes of scenes/*.toml: dimension, particle count and the first sentence of each file's
        opening comment.

Each key's row is a link target: {scene-key}`physics.kernel` in any page links to it.
"""
import ast
import inspect
import json
import re

from docutils import nodes
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

logger = logging.getLogger(__name__)

KIND_NAMES = {"float": "number", "int": "integer", "vec": "vector", "str": "string", "bool": "boolean",
              "blocks": "list of boxes", "boxes": "list of boxes", "gauges": "list of [[gauges]] tables",
              "dt": 'number, "auto" or "adaptive"', "bodies": "list of bodies"}


def key_rows(schema=None, prefix=""):
    """(section, dotted key, default, unit, range, type, meaning) of every key, in schema order; the
    default, range and meaning written as describe_schema (`sphcore keys`) writes them."""
    from sphcore.scene import SCHEMA, preset_note

    schema = SCHEMA if schema is None else schema
    rows = []
    for name, key in schema.items():
        if isinstance(key, dict):
            rows += key_rows(key, f"{prefix}{name}.")
            continue
        choice = "|" in key.kind
        span = (" | ".join(key.kind.split("|")) if choice else "" if key.kind in ("str", "bool", "gauges")
                else f"[{key.low:g}, {key.high:g}]")
        kind = "choice" if choice else KIND_NAMES.get(key.kind, key.kind)
        section = prefix.rstrip(".") or "(top level)"
        rows.append((section, f"{prefix}{name}", json.dumps(key.default), key.unit, span, kind,
                     key.doc + preset_note(f"{prefix}{name}")))
    return rows


def toml_value(value):
    """`value` as TOML writes it (a preset's keys are what a scene file would set)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return repr(value)


def preset_comments():
    """{configuration name: the comment lines just above its entry in CONFIGS} (sphcore.validate.configs)."""
    from sphcore.validate import configs

    lines = inspect.getsource(configs).splitlines()
    tree = ast.parse("\n".join(lines))
    found = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "CONFIGS" for t in node.targets):
            for k in node.value.keys:
                if not isinstance(k, ast.Constant):
                    continue
                comment, i = [], k.lineno - 2  # the line above the key (0-based)
                while i >= 0 and lines[i].strip().startswith("#"):
                    comment.insert(0, lines[i].strip().lstrip("#").strip())
                    i -= 1
                found[k.value] = re.sub(r"\bissue \d+: ", "", " ".join(comment))  # what it is, not when
    return found


def inline(text):
    """Paragraph children of `text`, its `backticked` spans as code."""
    out = []
    for i, part in enumerate(re.split(r"`([^`]+)`", text)):
        if part:
            out.append(nodes.literal(part, part) if i % 2 else nodes.Text(part))
    return out


def cell(*children):
    entry = nodes.entry()
    entry += nodes.paragraph("", "", *children)
    return entry


def code(text):
    return nodes.literal(text, text) if text else nodes.Text("")


def table(title, headers, widths, rows, classes=()):
    """A docutils table: `rows` are lists of (row ids, [entry, ...])."""
    tab = nodes.table(classes=["scene-table", *classes])
    if title:
        tab += nodes.title(title, title)
    group = nodes.tgroup(cols=len(headers))
    tab += group
    for w in widths:
        group += nodes.colspec(colwidth=w)
    head = nodes.thead()
    group += head
    row = nodes.row()
    for h in headers:
        row += cell(nodes.Text(h))
    head += row
    body = nodes.tbody()
    group += body
    for ids, entries in rows:
        row = nodes.row(ids=ids)
        for e in entries:
            row += e
        body += row
    return tab


def key_id(dotted):
    return "key-" + dotted.replace(".", "-").replace("_", "-")


class SceneKeys(SphinxDirective):
    """Every scene key, one table per section, generated from sphcore.scene.SCHEMA."""

    has_content = False

    def run(self):
        std = self.env.get_domain("std")
        sections = {}
        for section, dotted, default, unit, span, kind, doc in key_rows():
            sections.setdefault(section, []).append((dotted, default, unit, span, kind, doc))
        out = []
        for section, rows in sections.items():
            body = []
            for dotted, default, unit, span, kind, doc in rows:
                std.note_object("scene-key", dotted, key_id(dotted), location=self.get_location())
                body.append(([key_id(dotted)], [cell(code(dotted)), cell(code(default)), cell(code(unit)),
                                                cell(code(span)), cell(nodes.Text(kind)), cell(*inline(doc))]))
            out.append(table(f"[{section}]" if section != "(top level)" else "top level",
                             ["key", "default", "unit", "range", "type", "meaning"], [18, 12, 7, 14, 8, 41], body,
                             ["scene-keys"]))
        return out


class SceneModels(SphinxDirective):
    """The keys each physics.model sets, generated from sphcore.scene.PRESETS."""

    has_content = False

    def run(self):
        from sphcore.scene import DEFAULT_MODEL, PRESETS

        models = list(PRESETS)
        body = []
        for dotted in PRESETS[DEFAULT_MODEL]:
            body.append(([], [cell(code(dotted))] + [cell(code(toml_value(PRESETS[m][dotted]))) for m in models]))
        headers = ["key"] + [f"{m} (the default)" if m == DEFAULT_MODEL else m for m in models]
        return [table("the keys each physics.model sets", headers, [28] + [24] * len(models), body,
                      ["scene-models"])]


class ScenePresets(SphinxDirective):
    """The named model configurations of sphcore.validate.configs, generated from CONFIGS."""

    has_content = False

    def run(self):
        from sphcore.validate import configs

        comments = preset_comments()
        body = []
        for name, keys in configs.CONFIGS.items():
            notes = []
            if name == configs.DEFAULT_CONFIG:
                notes.append("the base every configuration is laid over (the validation cases name the graphics "
                             "model).")
            if name == configs.RECOMMENDED_CONFIG:
                notes.append("the recommended model for measured figures.")
            if comments.get(name):
                notes.append(comments[name])
            settings = nodes.paragraph()
            if not keys:
                settings += nodes.Text("(no keys: the scene defaults)")
            for i, (k, v) in enumerate(keys.items()):
                if i:
                    settings += nodes.Text(", ")
                settings += code(f"{k} = {toml_value(v)}")
            entry = nodes.entry()
            entry += settings
            body.append(([f"preset-{name.replace('_', '-')}"],
                         [cell(code(name)), entry, cell(*inline(" ".join(notes)))]))
        return [table("model configurations (presets)", ["name", "scene keys it sets", "note"], [14, 50, 36], body,
                      ["scene-presets"])]


class ShippedScenes(SphinxDirective):
    """The scenes in scenes/ (sphcore.scene.shipped_scenes): name, dimension, particles and the first
    sentence of the comment at the top of each file."""

    has_content = False

    def run(self):
        from sphcore.scene import Scene, scene_path, shipped_scenes

        body = []
        for name in shipped_scenes():
            path = scene_path(name)
            self.env.note_dependency(str(path))
            head = []
            for line in path.read_text(encoding="utf-8").splitlines():
                if not line.startswith("#"):
                    break
                head.append(line.lstrip("#").strip())
            first = re.split(r"(?<=\.)\s+(?=[A-Z])", " ".join(head), maxsplit=1)[0]
            scene = Scene.load(name)
            body.append(([f"scene-{name.replace('_', '-')}"],
                         [cell(code(name)), cell(nodes.Text(f"{scene.dim}D")),
                          cell(nodes.Text(f"{len(scene.initial_positions()):,}")), cell(*inline(first))]))
        return [table("shipped scenes (scenes/*.toml)", ["name", "dim", "particles", "what it is"], [14, 5, 9, 72],
                      body, ["shipped-scenes"])]


def unknown_key(app, env, node, contnode):
    """A {scene-key} role naming no key is a warning (an error under -W), not a silent plain word."""
    if node.get("reftype") == "scene-key":
        logger.warning("unknown scene key %r (`sphcore keys` lists them)", node["reftarget"], location=node)
    return None


def setup(app):
    app.add_crossref_type("scene-key", "scene-key", "pair: %s; scene key")
    app.connect("missing-reference", unknown_key)
    app.add_directive("scene-keys", SceneKeys)
    app.add_directive("scene-models", SceneModels)
    app.add_directive("scene-presets", ScenePresets)
    app.add_directive("shipped-scenes", ShippedScenes)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
