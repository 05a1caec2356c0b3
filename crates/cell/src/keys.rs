//! The cell's key expressions, all under `qmarc/cell/NAME/`.
//!
//! | key | who | what |
//! |---|---|---|
//! | `camera` | the camera (liveliness token) | the cell's camera is alive |
//! | `belt` | the camera (queryable) | the cell's belt, [`crate::wire::CellBelt`] |
//! | `parts` | the camera (publication) | each part once, [`crate::wire::WirePart`] |
//! | `recent` | the camera (queryable) | the parts of the last seconds, a list |
//! | `robot/ROBOT` | a robot (liveliness token) | the robot is alive |
//! | `member/ROBOT` | a robot (queryable) | its window and offset, [`crate::wire::WireMember`] |
//! | `claims/ROBOT` | a robot (publication) | its claims, picks, give-ups and parts let pass, [`crate::wire::WireClaim`] |
//! | `ledger/ROBOT` | a robot (queryable) | its claims not yet picked, and its picks and passes of the last minute, a list |

/// The key of `what` in cell `cell`.
pub fn key(cell: &str, what: &str) -> String {
    format!("qmarc/cell/{cell}/{what}")
}

/// The key of `what` of robot `robot` in cell `cell`.
pub fn robot_key(cell: &str, what: &str, robot: &str) -> String {
    format!("qmarc/cell/{cell}/{what}/{robot}")
}

/// The robot a key of `what` names (`…/what/ROBOT`), if it is one.
pub fn robot_of<'a>(key: &'a str, what: &str) -> Option<&'a str> {
    let (head, robot) = key.rsplit_once('/')?;
    head.ends_with(&format!("/{what}")).then_some(robot)
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_robots_key_names_it() {
        let k = super::robot_key("belt1", "robot", "west");
        assert_eq!(k, "qmarc/cell/belt1/robot/west");
        assert_eq!(super::robot_of(&k, "robot"), Some("west"));
        assert_eq!(super::robot_of(&k, "claims"), None);
        assert_eq!(super::key("belt1", "parts"), "qmarc/cell/belt1/parts");
    }
}
