//! The box's inputs other than its pins and the host's frames, as the models assume them.

use skinbox_protocol::box_counters::LinkSpeed;

/// The link state the box is given (its `link_up` and `link_speed` inputs, which the board
/// top drives from the PHY over MDIO): in a model run, and in the co-simulation harness,
/// there is no PHY, so the link is not reported up and its speed is not known. Status
/// datagrams and command acknowledgements carry it in their box counter block.
pub const LINK_UP: bool = false;
/// See [`LINK_UP`].
pub const LINK_SPEED: LinkSpeed = LinkSpeed::Unknown;
