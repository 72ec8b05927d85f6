//! Every error of planner-core is a `core::error::Error` whose message says what went
//! wrong in words (the first sentence of the variant's documentation, and its data), so
//! that an application can report it, box it or `?` it into its own error type.

use core::error::Error;
use planner_core::crossing::ManagerError;
use planner_core::free_space::FreeSpaceError;
use planner_core::intersection::LayoutError;
use planner_core::lateral::LateralError;
use planner_core::{
    ConfigError, InputError, LaneInputError, ParamsError, ProblemError, SolveError, WorldError,
};

/// `e`'s message contains `words`.
fn says(e: &dyn Error, words: &str) {
    let text = e.to_string();
    assert!(text.contains(words), "{text:?} should say {words:?}");
}

#[test]
fn every_error_says_what_went_wrong() {
    says(&ManagerError::UnknownRoute, "no such route");
    says(&ManagerError::Distrusted, "from a suspect");
    says(&FreeSpaceError::OutsideBand, "outside the band");
    says(&LayoutError::<f64>::NotPositive, "not positive");
    says(
        &LayoutError::NotSpacious {
            margin: 1.5,
            needed: 12.5,
        },
        "margin: 1.5",
    );
    says(&LateralError::NotConverged, "no convergence");
    says(&ProblemError::InvalidWeights, "a weight is negative");
    says(&ParamsError::DecelerationNotNegative, "a_min must be < 0");
    says(&InputError::SpeedOutOfRange, "vmax");
    says(&LaneInputError::LaneTooNarrow, "not wider than the vehicle");
    says(&ConfigError::InvalidLatency, "notification latency");
    says(&SolveError::NonFinite, "NaN");
    says(
        &SolveError::IterationLimit { iterations: 40 },
        "iterations: 40",
    );
    says(&WorldError::OwnMessage, "receiver's own");
}

#[test]
fn a_wrapped_error_says_its_cause_and_gives_it_as_its_source() {
    let e = LaneInputError::Speed(InputError::NotFinite);
    says(&e, "the speed part is invalid: a position, speed");
    let source = e.source().expect("the speed part's error");
    assert_eq!(source.to_string(), InputError::NotFinite.to_string());
    assert!(LaneInputError::LaneTooNarrow.source().is_none());
}

#[test]
fn an_error_goes_into_an_applications_own() {
    fn configure() -> Result<(), Box<dyn Error>> {
        Err(ConfigError::InvalidResolution)?
    }
    assert_eq!(
        configure().expect_err("refused").to_string(),
        "a bus resolution that is negative, not finite, or 1 or more"
    );
}
