//! Coherent point drift: rigid, affine and non-rigid registration (seed 000_3b1454b2b2194811.txt eq. 3.12–3.18).
