//! Polygon (chamber-opening) detection by Hough voting and IRLS (seed 000_3b1454b2b2194811.txt ch. 3.3).
