//! Integration tests of the `pssba` binary: every test runs the real executable, all compiled
//! into one test binary.

mod bags;
mod balm;
mod bench;
mod cli;
mod crash;
mod export;
mod flight;
mod kitti;
mod live;
mod point_times;
mod shared_data;
mod simulate;
mod system;
