//! Active auto-teaching: Fisher information, observability indices and pose planning (seed 000_3b1454b2b2194811.txt ch. 6).
