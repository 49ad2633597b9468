"""HDBSCAN* of a sparse neighbour graph: the labels of scikit-learn's
`HDBSCAN(metric="precomputed")` on that graph (excess of mass, no single cluster, no epsilon),
computed here because at a coast's scale the library's way costs more than the clustering.

Route clustering beyond `EXACT_TRACKS` tracks hands HDBSCAN the k-nearest-neighbour graph of the
tracks' endpoints. On the 99,584 tracks of `benchmarks/ingest_speed.py`, scikit-learn's estimator
took 0.5 s, most of it a Python loop over the rows to find each core distance, and importing
scikit-learn took 0.65 s more (it imports SciPy's statistics) in a command that runs in 7 s.
Here the same steps are compiled: core distances, mutual reachability, SciPy's minimum spanning
tree, the single-linkage tree, the condensed tree, the clusters' stabilities and the excess-of-
mass selection. Every step keeps the library's order (the spanning tree's edges sorted by the
same `np.argsort`, the trees walked breadth first, stabilities summed row by row), so tied
distances (vessels that start and end at the same berths) give the same labels too:
`tests/preprocess/test_routes.py` compares both on real and tie-heavy endpoints.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.sparse import coo_matrix, csgraph, csr_matrix


def neighbour_graph(x: np.ndarray, k: int) -> tuple[csr_matrix, np.ndarray]:
    """The symmetric graph of each point's `k` nearest neighbours in `x` (a k-d tree), and the
    distances to its k + 1 nearest (itself first, when no duplicate comes before it). Parts
    not joined by any neighbour are joined in a chain at a distance beyond every other, so
    each part is split (or kept) by its own hierarchy."""
    from scipy.spatial import cKDTree

    n = len(x)
    dist, nbr = cKDTree(x).query(x, k + 1, workers=-1)
    rows = np.repeat(np.arange(n), k + 1)
    keep = nbr.ravel() != rows
    i = np.minimum(rows[keep], nbr.ravel()[keep])
    j = np.maximum(rows[keep], nbr.ravel()[keep])
    # identical points (distance 0) would read as no edge in a sparse matrix
    data = np.maximum(dist.ravel()[keep], 1e-9)
    # each edge once: one found from both ends has the same distance both ways
    first = np.unique(i * n + j, return_index=True)[1]
    i, j, data = i[first], j[first], data[first]
    parts, part = csgraph.connected_components(coo_matrix((data, (i, j)), shape=(n, n)), False)
    if parts > 1:
        heads = np.unique(part, return_index=True)[1]
        i, j = np.r_[i, heads[:-1]], np.r_[j, heads[1:]]
        data = np.r_[data, np.full(parts - 1, 2.0 * float(data.max()) + 1.0)]
    graph = coo_matrix((np.r_[data, data], (np.r_[i, j], np.r_[j, i])), shape=(n, n)).tocsr()
    graph.sort_indices()
    return graph, dist


def hdbscan_labels(graph: csr_matrix, min_cluster_size: int, min_samples: int) -> np.ndarray:
    """Cluster label of each node of the symmetric distance `graph` (CSR, no diagonal, every
    row at least `min_samples` entries, connected), -1 for noise."""
    n = graph.shape[0]
    if n < 2 or np.diff(graph.indptr).min() < min_samples:
        raise ValueError(f"every point needs at least {min_samples} neighbours in the graph")
    data = np.asarray(graph.data, dtype=np.float64)
    reach = _mutual_reachability(graph.indptr, graph.indices, data, min_samples - 1)
    tree = csgraph.minimum_spanning_tree(
        csr_matrix((reach, graph.indices, graph.indptr), shape=graph.shape)
    )
    a, b = tree.nonzero()
    if len(a) != n - 1:
        raise ValueError("the graph is not connected: its points have no single hierarchy")
    height = tree.data
    order = np.argsort(height)  # the library's sort, ties and all
    left, right, size = _single_linkage(a[order].astype(np.int64), b[order].astype(np.int64))
    parent, child, lam, count = _condense(left, right, height[order], size, min_cluster_size)
    return _excess_of_mass_labels(parent, child, lam, count, n)


@njit(cache=True)
def _mutual_reachability(indptr, indices, data, kth):  # pragma: no cover - compiled
    """max(core(i), core(j), d(i, j)) for every edge; core(i) is the kth smallest distance
    in row i (scikit-learn takes it by `np.partition`: the same value)."""
    n = len(indptr) - 1
    core = np.empty(n)
    for i in range(n):
        core[i] = np.sort(data[indptr[i] : indptr[i + 1]])[kth]
    out = np.empty_like(data)
    for i in range(n):
        for e in range(indptr[i], indptr[i + 1]):
            out[e] = max(core[i], core[indices[e]], data[e])
    return out


@njit(cache=True)
def _root(parent, i):  # pragma: no cover - compiled
    top = i
    while parent[top] != -1:
        top = parent[top]
    while parent[i] != -1 and parent[i] != top:
        parent[i], i = top, parent[i]
    return top


@njit(cache=True)
def _single_linkage(a, b):  # pragma: no cover - compiled
    """The dendrogram (SciPy's linkage layout: merge e makes node n + e) of the spanning tree's
    edges, sorted by height: each merge joins the current clusters of its edge's two ends."""
    n = len(a) + 1
    parent = np.full(2 * n - 1, -1, dtype=np.int64)
    size = np.zeros(2 * n - 1, dtype=np.int64)
    size[:n] = 1
    left = np.empty(n - 1, dtype=np.int64)
    right = np.empty(n - 1, dtype=np.int64)
    merged = np.empty(n - 1, dtype=np.int64)
    for e in range(n - 1):
        x, y = _root(parent, a[e]), _root(parent, b[e])
        left[e], right[e] = x, y
        merged[e] = size[x] + size[y]
        parent[x] = parent[y] = n + e
        size[n + e] = merged[e]
    return left, right, merged


@njit(cache=True)
def _breadth_first(left, right, start, out):  # pragma: no cover - compiled
    """Nodes of the dendrogram under `start` (itself included) in breadth-first order, into
    `out`; returns how many."""
    n = len(left) + 1
    out[0] = start
    head, tail = 0, 1
    while head < tail:
        node = out[head]
        head += 1
        if node >= n:
            out[tail], out[tail + 1] = left[node - n], right[node - n]
            tail += 2
    return tail


@njit(cache=True)
def _condense(left, right, height, size, min_size):  # pragma: no cover - compiled
    """The condensed tree as rows (parent cluster, child, lambda = 1 / distance, child size):
    walking the dendrogram from the top, a split into two parts of at least `min_size` makes two
    new clusters; a smaller part's points fall out of the cluster at that lambda."""
    n = len(left) + 1
    root = 2 * (n - 1)
    order = np.empty(2 * n - 1, dtype=np.int64)
    _breadth_first(left, right, root, order)
    sub = np.empty(2 * n - 1, dtype=np.int64)
    relabel = np.empty(root + 1, dtype=np.int64)
    relabel[root] = n
    ignore = np.zeros(root + 1, dtype=np.bool_)
    cap = 3 * n
    parent = np.empty(cap, dtype=np.int64)
    child = np.empty(cap, dtype=np.int64)
    lam = np.empty(cap)
    count = np.empty(cap, dtype=np.int64)
    rows = 0
    label = n + 1
    for node in order:
        if ignore[node] or node < n:
            continue
        lo, hi = left[node - n], right[node - n]
        value = 1.0 / height[node - n] if height[node - n] > 0.0 else np.inf
        lo_size = size[lo - n] if lo >= n else 1
        hi_size = size[hi - n] if hi >= n else 1
        if lo_size >= min_size and hi_size >= min_size:
            for part, part_size in ((lo, lo_size), (hi, hi_size)):
                relabel[part] = label
                label += 1
                parent[rows], child[rows], lam[rows], count[rows] = (
                    relabel[node],
                    relabel[part],
                    value,
                    part_size,
                )
                rows += 1
            continue
        if lo_size >= min_size:
            relabel[lo] = relabel[node]
        if hi_size >= min_size:
            relabel[hi] = relabel[node]
        for part, part_size in ((lo, lo_size), (hi, hi_size)):
            if part_size >= min_size:
                continue
            for k in range(_breadth_first(left, right, part, sub)):
                if sub[k] < n:
                    parent[rows], child[rows], lam[rows], count[rows] = (
                        relabel[node],
                        sub[k],
                        value,
                        1,
                    )
                    rows += 1
                ignore[sub[k]] = True
    return parent[:rows], child[:rows], lam[:rows], count[:rows]


@njit(cache=True)
def _excess_of_mass_labels(parent, child, lam, count, n):  # pragma: no cover - compiled
    """Labels 0, 1, ... (clusters in the order of their ids) of the excess-of-mass clusters, the
    root excluded: a cluster is kept when its stability (the sum over its rows of (lambda -
    its birth lambda) x size) is at least its children's kept stability; a kept cluster's
    descendants are not clusters. A point takes the nearest selected cluster above it."""
    top = n + 1
    for i in range(len(parent)):
        top = max(top, parent[i] + 1, child[i] + 1)
    birth = np.zeros(top)
    up = np.full(top, -1, dtype=np.int64)
    first = np.full(top, -1, dtype=np.int64)  # a cluster's two children in the tree
    second = np.full(top, -1, dtype=np.int64)
    for i in range(len(parent)):
        birth[child[i]] = lam[i]
        if count[i] > 1:
            up[child[i]] = parent[i]
            if first[parent[i]] == -1:
                first[parent[i]] = child[i]
            else:
                second[parent[i]] = child[i]
    birth[n] = 0.0
    stability = np.zeros(top)
    for i in range(len(parent)):
        stability[parent[i]] += (lam[i] - birth[parent[i]]) * count[i]
    kept = np.zeros(top, dtype=np.bool_)
    for node in range(top - 1, n, -1):
        below = 0.0
        if first[node] != -1:
            below = stability[first[node]] + stability[second[node]]
        if below > stability[node]:
            stability[node] = below
        else:
            kept[node] = True
    chosen = np.full(top, -1, dtype=np.int64)  # the selected cluster at or above each cluster
    number = np.full(top, -1, dtype=np.int64)
    clusters = 0
    for node in range(n + 1, top):
        above = chosen[up[node]]
        if above == -1 and kept[node]:
            chosen[node] = node
            number[node] = clusters
            clusters += 1
        else:
            chosen[node] = above
    labels = np.full(n, -1, dtype=np.int64)
    for i in range(len(parent)):
        if count[i] == 1 and chosen[parent[i]] != -1:
            labels[child[i]] = number[chosen[parent[i]]]
    return labels
