"""Models that declare only the opset domains their nodes use.

onnxruntime's quantiser copies every domain it knows into ``opset_import`` (nine of them:
``ai.onnx.ml`` 5, ``ai.onnx.training``, ``com.microsoft.nchwc``, ``org.pytorch.aten`` ...),
whether or not a node uses it. An older onnxruntime refuses a model that declares a domain
version it does not know (1.16: ``ai.onnx.ml`` 5), so a box on an older runtime could not
load the int8 models although every operator in them is one it runs.

:func:`declare_used_opsets` keeps the default domain and the domains a node of the graph,
of a subgraph or of a local function uses, at their declared versions. The export path
applies it to every model it writes (``export.onnx_export.save_onnx``,
``export.quantize.build_variant``), so a rebuild (``make assets``, ``python -m export
lifter``) ships lean declarations by itself; :func:`apply_to_assets` (``python -m export
opsets``) rewrites the models of an assets directory in place and updates their manifest
entries (sha256, size). It changes only ``opset_import``: the graph and its weights, and
so the outputs, are the same.

Imports onnx only (no torch, no onnxruntime), so the command runs on an export machine
without the training extra's torch.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterator

import onnx

DEFAULT_DOMAINS = ("", "ai.onnx")
"""The default operator set, always declared (its two spellings)."""


def _nodes(graph: onnx.GraphProto) -> Iterator[onnx.NodeProto]:
    """Every node of ``graph`` and of its subgraphs (If, Loop, Scan bodies), depth first."""
    for n in graph.node:
        yield n
        for a in n.attribute:
            if a.type == onnx.AttributeProto.GRAPH:
                yield from _nodes(a.g)
            elif a.type == onnx.AttributeProto.GRAPHS:
                for g in a.graphs:
                    yield from _nodes(g)


def used_domains(model: onnx.ModelProto) -> set[str]:
    """The operator domains the model's nodes use (graph, subgraphs, local functions) and
    the domains of its local functions (a call names the function's domain)."""
    domains = {n.domain for n in _nodes(model.graph)}
    for f in model.functions:
        domains.update(n.domain for n in f.node)
    return domains


def declare_used_opsets(model: onnx.ModelProto) -> onnx.ModelProto:
    """Drop from ``model.opset_import`` (in place) every domain no node uses; returns ``model``.

    Order and versions of the kept entries are unchanged, so a model that already declares
    only what it uses serialises to the same bytes."""
    used = used_domains(model) | set(DEFAULT_DOMAINS)
    keep = [o for o in model.opset_import if o.domain in used]
    if len(keep) != len(model.opset_import):
        del model.opset_import[:]
        model.opset_import.extend(keep)
    return model


def apply_to_assets(assets_dir: str | Path) -> list[str]:
    """Rewrite each model of ``assets_dir/manifest.json`` that declares unused domains and
    update its entry's ``sha256`` and ``size_bytes``; returns the files rewritten. Idempotent:
    a second run rewrites nothing. The manifest's sha256 is checked before a file is touched."""
    from edge_runtime.core.manifest import load_manifest, manifest_path, read_verified, sha256_bytes, write_manifest

    base = manifest_path(assets_dir).parent
    manifest = load_manifest(assets_dir)
    changed = []
    for entry in manifest["models"]:
        path = base / entry["file"]
        model = onnx.load_from_string(read_verified(base, entry))
        before = len(model.opset_import)
        if len(declare_used_opsets(model).opset_import) == before:
            continue
        new = model.SerializeToString(deterministic=True)
        path.write_bytes(new)
        entry.update(sha256=sha256_bytes(new), size_bytes=len(new))
        changed.append(path.name)
    if changed:
        write_manifest(base, manifest)
    return changed
