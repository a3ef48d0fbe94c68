//! iceoryx2 failures, read by their error types and turned into the
//! [`TransportError`] the person running slamd should see.
//!
//! Each iceoryx2 error type slamd meets implements [`Explain`]: a match on
//! its variants names the [`Verdict`], and [`classify`] words the verdict
//! for the service and namespace at hand. A variant not listed is reported
//! as [`TransportError::Other`] with iceoryx2's own error.

use super::TransportError;
use iceoryx2::port::listener::ListenerCreateError;
use iceoryx2::port::notifier::NotifierCreateError;
use iceoryx2::port::publisher::PublisherCreateError;
use iceoryx2::port::subscriber::SubscriberCreateError;
use iceoryx2::port::SendError;
use iceoryx2::service::builder::event::{EventOpenError, EventOpenOrCreateError};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use std::fmt;

/// What an iceoryx2 failure says about the other side, whatever the
/// operation that met it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Verdict {
    /// The service does not exist: no daemon created it.
    Missing,
    /// The service does not carry this build's protocol attribute.
    OtherProtocol,
    /// The service carries another payload or user-header type.
    OtherLayout,
    /// The receiver's queue stayed full until the backpressure handler gave
    /// up.
    Full,
    /// Nothing slamd can explain better than iceoryx2's own error.
    Unexplained,
}

/// An iceoryx2 error type whose variants slamd knows how to explain.
pub(crate) trait Explain: fmt::Debug {
    /// The verdict for this error's variant.
    fn verdict(&self) -> Verdict;
}

impl Explain for PublishSubscribeOpenError {
    fn verdict(&self) -> Verdict {
        match self {
            Self::DoesNotExist => Verdict::Missing,
            Self::IncompatibleAttributes => Verdict::OtherProtocol,
            Self::IncompatibleTypes => Verdict::OtherLayout,
            _ => Verdict::Unexplained,
        }
    }
}

impl Explain for PublishSubscribeOpenOrCreateError {
    fn verdict(&self) -> Verdict {
        match self {
            Self::PublishSubscribeOpenError(e) => e.verdict(),
            _ => Verdict::Unexplained,
        }
    }
}

impl Explain for EventOpenError {
    fn verdict(&self) -> Verdict {
        match self {
            Self::DoesNotExist => Verdict::Missing,
            Self::IncompatibleAttributes => Verdict::OtherProtocol,
            _ => Verdict::Unexplained,
        }
    }
}

impl Explain for EventOpenOrCreateError {
    fn verdict(&self) -> Verdict {
        match self {
            Self::EventOpenError(e) => e.verdict(),
            _ => Verdict::Unexplained,
        }
    }
}

impl Explain for SendError {
    fn verdict(&self) -> Verdict {
        match self {
            Self::UnableToDeliver => Verdict::Full,
            _ => Verdict::Unexplained,
        }
    }
}

/// Port creation fails only for reasons local to the port (limits, memory,
/// tags); none of them says anything about the daemon.
macro_rules! unexplained {
    ($($error:ty),* $(,)?) => {
        $(impl Explain for $error {
            fn verdict(&self) -> Verdict {
                Verdict::Unexplained
            }
        })*
    };
}

unexplained!(
    PublisherCreateError,
    SubscriberCreateError,
    NotifierCreateError,
    ListenerCreateError,
);

/// Words `e`, met while doing `operation` on `service` of `namespace`:
/// [`Verdict::Missing`] is [`TransportError::NoDaemon`],
/// [`Verdict::OtherProtocol`] is [`TransportError::ProtocolMismatch`],
/// [`Verdict::OtherLayout`] is [`TransportError::IncompatibleLayout`],
/// [`Verdict::Full`] is [`TransportError::Backpressure`], and anything else
/// is [`TransportError::Other`] with the operation "`operation` \`service\`"
/// and iceoryx2's error as the cause.
pub(crate) fn classify(operation: &str, namespace: &str, service: &str, e: &impl Explain) -> TransportError {
    match e.verdict() {
        Verdict::Missing => TransportError::NoDaemon {
            namespace: namespace.into(),
        },
        Verdict::OtherProtocol => TransportError::ProtocolMismatch {
            service: service.into(),
        },
        Verdict::OtherLayout => TransportError::IncompatibleLayout {
            service: service.into(),
        },
        Verdict::Full => TransportError::Backpressure {
            service: service.into(),
        },
        Verdict::Unexplained => TransportError::other(&format!("{operation} `{service}`"), e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn open(e: &impl Explain) -> TransportError {
        classify("open", "ns", "ns/poses", e)
    }

    #[test]
    fn a_missing_service_means_no_daemon_however_it_was_reached() {
        let no_daemon = TransportError::NoDaemon {
            namespace: "ns".into(),
        };
        let ps = PublishSubscribeOpenError::DoesNotExist;
        assert_eq!(open(&ps), no_daemon);
        assert_eq!(open(&PublishSubscribeOpenOrCreateError::from(ps)), no_daemon);
        let ev = EventOpenError::DoesNotExist;
        assert_eq!(open(&ev), no_daemon);
        assert_eq!(open(&EventOpenOrCreateError::from(ev)), no_daemon);
    }

    #[test]
    fn other_attributes_mean_another_protocol_and_other_types_another_layout() {
        let mismatch = TransportError::ProtocolMismatch {
            service: "ns/poses".into(),
        };
        let ps = PublishSubscribeOpenError::IncompatibleAttributes;
        assert_eq!(open(&ps), mismatch);
        assert_eq!(open(&PublishSubscribeOpenOrCreateError::from(ps)), mismatch);
        let ev = EventOpenError::IncompatibleAttributes;
        assert_eq!(open(&EventOpenOrCreateError::from(ev)), mismatch);
        let layout = TransportError::IncompatibleLayout {
            service: "ns/poses".into(),
        };
        let types = PublishSubscribeOpenError::IncompatibleTypes;
        assert_eq!(open(&PublishSubscribeOpenOrCreateError::from(types)), layout);
    }

    #[test]
    fn only_an_undeliverable_send_is_backpressure() {
        let e = classify("send on", "ns", "ns/edges", &SendError::UnableToDeliver);
        assert_eq!(
            e,
            TransportError::Backpressure {
                service: "ns/edges".into()
            }
        );
        let e = classify("send on", "ns", "ns/edges", &SendError::ConnectionCorrupted);
        assert_eq!(
            e,
            TransportError::Other {
                operation: "send on `ns/edges`".into(),
                cause: "ConnectionCorrupted".into(),
            }
        );
    }

    #[test]
    fn everything_else_keeps_the_operation_and_iceoryx2s_error() {
        let e = open(&PublishSubscribeOpenError::VersionMismatch);
        assert_eq!(
            e,
            TransportError::Other {
                operation: "open `ns/poses`".into(),
                cause: "VersionMismatch".into(),
            }
        );
        let e = classify(
            "create",
            "ns",
            "ns/poses",
            &PublishSubscribeOpenOrCreateError::SystemInFlux,
        );
        assert!(matches!(e, TransportError::Other { .. }), "{e:?}");
        let e = open(&PublisherCreateError::ExceedsMaxSupportedPublishers);
        assert!(matches!(e, TransportError::Other { .. }), "{e:?}");
    }
}
