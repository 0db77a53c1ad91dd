//! Sparse nonlinear least squares on manifolds (seed 000_3b1454b2b2194811.txt ch. 5.3; 004_815695db12a6b16c.txt ch. 3, 5).
