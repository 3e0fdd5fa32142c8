//! The progressive schedule (DESIGN step 9, paper section "Notations and System Overview"):
//! smooth at gamma (steps 1-7), adjust the poses (step 8), stop when the pose change is below
//! T_conv, else gamma <- gamma / k. [`progressive`] holds it as a step-by-step state machine,
//! so smoothing and adjustment can run in different processes; [`pipeline`] runs it to the end
//! in one call; [`sliding`] runs it on sliding windows over a stream of frames (DESIGN
//! section 6); [`flight`] adds keyframes and loop closure over a whole flight (section 9). Dependencies go one way: `pipeline` and `sliding` drive `progressive`.

pub mod flight;
pub(crate) mod pipeline;
pub(crate) mod progressive;
pub mod sliding;
