//! Edge detection and edge-chain linking into arcs (seed 000_3b1454b2b2194811.txt ch. 3.1).
