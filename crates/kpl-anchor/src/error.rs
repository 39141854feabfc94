//! The errors of this crate: building an engine from a spec ([`BuildError`]), a step that cannot
//! be taken ([`StepError`]; nothing changes), and an identification that cannot be asked
//! ([`IdentifyError`]). Problems with single objects during a step are not errors but
//! [`crate::Warning`]s: the step goes on without them.

use kpl_core::Time;

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BuildError {
    #[error("link `{link}`: type `{ty}` is not declared")]
    UnknownType { link: String, ty: String },
    #[error("link `{link}`: no implementation of the link unit `{entry}` (known: {known})")]
    UnknownLinkUnit { link: String, entry: String, known: String },
    #[error("prediction model of `{ty}`: no implementation of `{entry}` (known: {known})")]
    UnknownModel { ty: String, entry: String, known: String },
    #[error("`{entry}`: {message}")]
    Implementation { entry: String, message: String },
    #[error("link `{link}`, {condition} condition: {}", messages.join("; "))]
    Condition { link: String, condition: &'static str, messages: Vec<String> },
    #[error("links form a cycle through the types {}: a type cannot be linked (even indirectly) into itself", types.join(", "))]
    Cycle { types: Vec<String> },
    #[error("identification `{name}`: {message}")]
    Identification { name: String, message: String },
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepError {
    #[error("no link `{0}` in this engine")]
    UnknownLink(String),
    #[error("time {time} is not after the previous step's time {previous}")]
    TimeNotIncreasing { time: Time, previous: Time },
    #[error("snapshot from `{source_name}`: type `{ty}` is not declared")]
    UnknownType { source_name: String, ty: String },
    #[error(
        "snapshot from `{source_name}`: objects of type `{ty}` are made by link `{link}`, not by a source"
    )]
    NotAPerceptType { source_name: String, ty: String, link: String },
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IdentifyError {
    #[error("type `{0}` is not declared")]
    UnknownType(String),
    #[error("no link leads into `{0}`: an identification is completed by a link into its type")]
    NoLinkInto(String),
    #[error("the name `{0}` is already in use")]
    NameInUse(String),
    #[error("the description does not compile: {}", .0.join("; "))]
    Description(Vec<String>),
}
