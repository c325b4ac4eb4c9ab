//! Synthetic parts with known defects, pose and outliers, for accuracy tests.
