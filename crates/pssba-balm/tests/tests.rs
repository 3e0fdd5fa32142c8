//! All integration tests of pssba-balm, compiled into one binary.

mod common;

mod bad_input;
mod cluster_cost;
mod config;
mod derivatives;
mod plane_scene;
mod serial_twin;
