//! ECS systems.
