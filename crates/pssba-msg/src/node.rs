//! Nodes, service names and the port settings every service of an instance shares
//! (iceoryx2 checks builder settings as requirements between processes, so each service is
//! built by exactly one function: the public ones in [`crate::public::services`], the internal
//! ones in [`crate::internal::services`]).
//!
//! Names: every service of an instance is `pssba/<instance>/<suffix>`, and every node of the
//! instance uses the iceoryx2 prefix [`crate::instance::prefix`], so two instances never see
//! each other. A run started by the launcher on files is the instance `run` under a prefix of
//! its own.

use crate::error::ServiceError;
use iceoryx2::port::listener::ListenerWaitError;
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use std::time::Duration;

/// The event service paired with a publish-subscribe service.
pub type EventService = event::PortFactory<ipc::Service>;

/// Creates this process's node under the iceoryx2 `prefix` (nodes of different prefixes never
/// see each other), then removes the resources of the prefix's dead nodes (iceoryx2's
/// dead-node detection).
pub fn create_node(prefix: &str, name: &str) -> Result<Node<ipc::Service>, ServiceError> {
    let config = config_with_prefix(prefix)?;
    let node_name =
        NodeName::new(name).map_err(|e| ServiceError::ipc(format!("node name {name:?}"), e))?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .config(&config)
        .create::<ipc::Service>()
        .map_err(|e| ServiceError::ipc(format!("node {name}"), e))?;
    // The ports of a crashed process (a stage this one replaces, a producer killed earlier)
    // leave the services first, so this process can attach in their place.
    node.try_cleanup_dead_nodes();
    Ok(node)
}

fn config_with_prefix(prefix: &str) -> Result<Config, ServiceError> {
    let mut config = Config::default();
    config.global.prefix = FileName::new(prefix.as_bytes())
        .map_err(|e| ServiceError::ipc(format!("prefix {prefix:?}"), e))?;
    Ok(config)
}

/// Names of the live (alive, not dead) iceoryx2 nodes under `prefix`: tells whether a system
/// or an outside process is attached to an instance.
pub fn alive_node_names(prefix: &str) -> Result<Vec<String>, ServiceError> {
    Ok(node_names(prefix)?
        .into_iter()
        .filter_map(|(name, alive)| alive.then_some(name))
        .collect())
}

/// Names of the iceoryx2 nodes under `prefix`, each with true if its process is alive, false
/// if it died and its resources are not cleaned yet.
pub fn node_names(prefix: &str) -> Result<Vec<(String, bool)>, ServiceError> {
    use iceoryx2::node::NodeView;
    let config = config_with_prefix(prefix)?;
    let mut names = Vec::new();
    Node::<ipc::Service>::list(&config, |state| {
        match state {
            NodeState::Alive(view) => {
                if let Some(details) = view.details() {
                    names.push((details.name().as_str().to_string(), true));
                }
            }
            NodeState::Dead(view) => {
                if let Some(details) = view.details() {
                    names.push((details.name().as_str().to_string(), false));
                }
            }
            _ => {}
        }
        CallbackProgression::Continue
    })
    .map_err(|e| ServiceError::ipc(format!("listing the nodes of {prefix}"), e))?;
    Ok(names)
}

/// Removes the iceoryx2 resources of every dead node under `prefix` (a process that crashed
/// or was killed), with iceoryx2's own dead-node detection; their ports leave every service,
/// so a restarted process can attach again and a new run is never blocked by an old crash.
/// Returns how many dead nodes were cleaned.
pub fn remove_dead_nodes(prefix: &str) -> Result<usize, ServiceError> {
    let config = config_with_prefix(prefix)?;
    let mut dead = Vec::new();
    Node::<ipc::Service>::list(&config, |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    })
    .map_err(|e| ServiceError::ipc(format!("listing the nodes of {prefix}"), e))?;
    let mut cleaned = 0;
    for view in dead {
        // Err: another process is cleaning it up already, or it is gone; both are fine.
        if view.try_remove_stale_resources().is_ok() {
            cleaned += 1;
        }
    }
    Ok(cleaned)
}

/// The full name of service `suffix` of the node's instance: `pssba/<instance>/<suffix>`.
pub fn full_name(node: &Node<ipc::Service>, suffix: &str) -> String {
    let prefix = node.config().global.prefix.to_string();
    format!(
        "pssba/{}/{suffix}",
        crate::instance::from_prefix(&prefix).unwrap_or(crate::instance::RUN)
    )
}

/// The iceoryx2 service name of `suffix` for the node's instance.
pub fn service_name(node: &Node<ipc::Service>, suffix: &str) -> Result<ServiceName, ServiceError> {
    let name = full_name(node, suffix);
    ServiceName::new(&name).map_err(|e| ServiceError::ipc(format!("service name {name:?}"), e))
}

/// Opens or creates a lossless publish-subscribe service (no safe overflow, a publisher waits
/// while a subscriber's queue is full) with a user header, exact subscriber count and queue
/// length.
#[macro_export]
macro_rules! lossless_service {
    ($node:expr, $suffix:expr, $payload:ty, $header:ty, $subscribers:expr, $buffer:expr) => {{
        let name = $crate::node::service_name($node, $suffix)?;
        $node
            .service_builder(&name)
            .publish_subscribe::<$payload>()
            .user_header::<$header>()
            .max_publishers(1)
            .max_subscribers($subscribers)
            .history_size(0)
            .subscriber_max_buffer_size($buffer)
            .subscriber_max_borrowed_samples(1)
            .enable_safe_overflow(false)
            .open_or_create()
            .map_err(|e| $crate::ServiceError::ipc(format!("service {}", name.as_str()), e))
    }};
}

/// Opens or creates the event service paired with service `suffix` (`.../<suffix>/event`).
pub fn event_service(
    node: &Node<ipc::Service>,
    suffix: &str,
) -> Result<EventService, ServiceError> {
    let name = service_name(node, &format!("{suffix}/event"))?;
    node.service_builder(&name)
        .event()
        .max_notifiers(4)
        .max_listeners(4)
        .open_or_create()
        .map_err(|e| ServiceError::ipc(format!("event service {}", name.as_str()), e))
}

/// The backpressure handler of every lossless publisher: wait (iceoryx2's adaptive wait, not
/// a spin) while a subscriber's buffer is full, give up after `timeout` so a stuck consumer
/// makes the send fail with an error instead of hanging the producer forever.
pub fn backpressure_handler(
    timeout: Duration,
) -> impl Fn(&BackpressureInfo) -> BackpressureAction + Send + 'static {
    move |info: &BackpressureInfo| {
        if info.elapsed_time > timeout {
            BackpressureAction::DiscardDataAndFail
        } else {
            BackpressureAction::Retry
        }
    }
}

/// Creates a publisher whose samples hold up to `max_slice_len` elements, allocated once
/// (static: iceoryx2 0.10 can lose a sample when a growing segment is replaced before a
/// subscriber has mapped it, seen here as a missing frame), with the shared backpressure
/// handler.
pub fn publisher<P, H>(
    service: &publish_subscribe::PortFactory<ipc::Service, [P], H>,
    max_slice_len: usize,
    backpressure_timeout: Duration,
) -> Result<iceoryx2::port::publisher::Publisher<ipc::Service, [P], H>, ServiceError>
where
    P: std::fmt::Debug + ZeroCopySend + 'static,
    H: std::fmt::Debug + ZeroCopySend + 'static,
{
    service
        .publisher_builder()
        .initial_max_slice_len(max_slice_len.max(1))
        .allocation_strategy(AllocationStrategy::Static)
        .max_loaned_samples(1)
        .set_backpressure_handler(backpressure_handler(backpressure_timeout))
        .create()
        .map_err(|e| ServiceError::ipc("publisher", e))
}

/// A listener wait ended by a signal (EINTR: any signal this process handles, e.g. the
/// iceoryx2 or Ctrl-C handlers of the program) is a spurious wake-up, as a timeout is: the
/// caller looks for data and checks its own termination flag, then waits again. Only a
/// broken listener is an error.
pub fn woken(result: Result<u64, ListenerWaitError>) -> Result<(), ListenerWaitError> {
    match result {
        Ok(_) | Err(ListenerWaitError::InterruptSignal) => Ok(()),
        Err(error) => Err(error),
    }
}
