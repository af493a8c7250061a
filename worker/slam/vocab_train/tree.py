"""A vocabulary tree from binary descriptors: hierarchical k-majority (DBoW2's HKmeans), then idf weights.

Each node's descriptors are split into k clusters, recursively, `levels` deep; a node with at most k
descriptors gets one leaf per descriptor (as DBoW2 does). Leaves are the words. A word's idf is
log(N / n_w), N training images, n_w of them with at least one descriptor of that word.
"""
from __future__ import annotations

from collections import deque
from collections.abc import Iterable

import numpy as np

from worker.slam.features.vocabulary import Vocabulary
from worker.slam.vocab_train.kmajority import kmajority


def build_tree(desc: np.ndarray, k: int, levels: int, rng: np.random.Generator,
               max_iter: int = 15) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """((M, 32) uint8 centres, (M, k) int32 children, (M,) int8 depth) of the tree over (N, 32) uint8 `desc`."""
    centres = [np.zeros(desc.shape[1], np.uint8)]
    children = [np.full(k, -1, np.int32)]
    depth = [0]
    todo = deque([(0, np.arange(len(desc)))])  # (node, its descriptors), breadth first
    while todo:
        node, members = todo.popleft()
        if depth[node] >= levels or len(members) == 0:
            continue
        if len(members) <= k:
            cents, labels = desc[members], np.arange(len(members))
        else:
            cents, labels = kmajority(desc[members], k, rng, max_iter)
        for c in range(len(cents)):
            child = len(centres)
            centres.append(cents[c])
            children.append(np.full(k, -1, np.int32))
            depth.append(depth[node] + 1)
            children[node][c] = child
            todo.append((child, members[labels == c]))
    return np.stack(centres), np.stack(children), np.array(depth, np.int8)


def vocabulary_from_tree(centres: np.ndarray, children: np.ndarray, depth: np.ndarray,
                         images: Iterable[np.ndarray]) -> Vocabulary:
    """The vocabulary with its leaves numbered as words and idf counted over `images` (each (N, 32) uint8)."""
    leaf = np.asarray((children < 0).all(1))
    leaf[0] = False
    word_of = np.full(len(centres), -1, np.int32)
    word_of[leaf] = np.arange(leaf.sum(), dtype=np.int32)
    voc = Vocabulary(centres, children, word_of, np.ones(int(leaf.sum()), np.float32), depth)
    n_images = 0
    seen = np.zeros(voc.n_words, np.int64)
    for d in images:
        if len(d):
            seen[np.unique(voc.words(d))] += 1
            n_images += 1
    idf = np.log(max(n_images, 1) / np.maximum(seen, 1)).astype(np.float32)
    return Vocabulary(centres, children, word_of, idf, depth)
