"""Data association: gating, independent clusters, global nearest neighbour."""

from trackers.association.clusters import PairClusters, cluster_pairs
from trackers.association.gating import GatedPairs, gate
from trackers.association.gnn import gnn_assign

__all__ = ["GatedPairs", "PairClusters", "cluster_pairs", "gate", "gnn_assign"]
