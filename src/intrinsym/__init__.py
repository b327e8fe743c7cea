"""intrinsym: partial intrinsic symmetries with an MRF and loopy belief propagation."""
