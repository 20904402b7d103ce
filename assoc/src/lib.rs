//! assoc
