//! The pure core: the paper's model, the prototype's sensors and actuators, the estimator, the
//! controller and the vehicle that steps them at fixed rates. What passes between plant, sensors
//! and controller is in [`signals`], so none of them imports another's types. Nothing here reads
//! a clock, opens a file or a socket, or knows MAVLink's transports.

pub mod airframe;
pub mod control;
pub mod estimator;
pub mod estimator_forward;
pub mod frames;
pub mod integrator;
pub mod mode;
pub mod plant;
pub mod sensors;
pub mod signals;
pub mod vehicle;
