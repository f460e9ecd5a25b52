"""Array helpers under the EM and the sweeps: geometry, moments, neighbours, voxels."""
