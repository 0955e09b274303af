#!/usr/bin/env python3
"""Writes the glTF regression inputs (python3 stdlib only); see fuzz_regressions_test.cpp.

Run from anywhere: python3 tests/data/gltf/regressions/make_regressions.py
"""
import json
import os

HERE = os.path.dirname(os.path.abspath(__file__))


def write(name, document):
    with open(os.path.join(HERE, name), "w") as f:
        json.dump(document, f, separators=(",", ":"))


# 40 levels, each node listing the next one twice: 2^40 root-to-leaf paths.
# Visiting every path hung the loader.
write("shared_node_explosion.gltf", {
    "asset": {"version": "2.0"},
    "nodes": [{"children": [i + 1, i + 1]} for i in range(40)] + [{}],
    "scenes": [{"nodes": [0]}],
})

# A chain of 1200 nodes: one recursion level per node (a long enough chain
# overflows the stack; 1000 levels are allowed).
write("deep_node_chain.gltf", {
    "asset": {"version": "2.0"},
    "nodes": [{"children": [i + 1]} for i in range(1199)] + [{}],
    "scenes": [{"nodes": [0]}],
})
