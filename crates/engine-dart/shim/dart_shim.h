// The C++ shim between realitygap's DART engine (Rust, through cxx) and
// DART 6.12's C++ API. Kept thin: it builds skeletons, sets commands, steps
// and reads state; every decision (model planning, servo laws, checks) is
// on the Rust side. Every entry point that calls DART catches what DART
// throws and what it prints (see dart_shim.cc).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>

#include "rust/cxx.h"

namespace rgdart {

class World;
struct StepReport;

rust::String dart_version();
rust::String take_messages();
void say(rust::Str text);

std::unique_ptr<World> new_world(
    double timestep_s,
    rust::Slice<const double> gravity,
    rust::Str detector,
    rust::Str lcp);

struct WorldImpl;

class World
{
public:
  explicit World(std::unique_ptr<WorldImpl> impl);
  ~World();

  std::size_t add_robot_body(
      rust::Str name,
      std::int64_t parent,
      std::uint8_t kind,
      rust::Slice<const double> joint_pose,
      rust::Slice<const double> axis,
      double mass_kg,
      rust::Slice<const double> com,
      rust::Slice<const double> inertia);
  void set_joint_limits(std::size_t joint, double lower, double upper);
  void set_joint_friction(std::size_t joint, double friction);
  void set_actuator(std::size_t joint, bool servo, double limit);
  void set_drives(
      rust::Slice<const double> command,
      rust::Slice<const double> damping,
      rust::Slice<const double> stiffness,
      rust::Slice<const double> rest);
  void add_shape(
      bool object,
      std::size_t body,
      std::uint8_t kind,
      rust::Slice<const double> dims,
      rust::Slice<const double> pose,
      double friction,
      double restitution);
  void add_mesh(
      std::size_t body,
      rust::Slice<const double> vertices,
      rust::Slice<const std::uint32_t> indices,
      rust::Slice<const double> pose,
      double friction);
  std::size_t add_object(
      rust::Str name,
      double mass_kg,
      rust::Slice<const double> inertia,
      rust::Slice<const double> pose);
  void add_ground(double height, double friction, double restitution);
  void finish();
  void step();
  void step_raw(std::uint64_t n);
  StepReport advance(
      rust::Slice<const double> command,
      rust::Slice<const double> damping,
      rust::Slice<const double> stiffness,
      rust::Slice<const double> rest,
      rust::Slice<double> positions,
      rust::Slice<double> velocities);
  void joint_state(
      rust::Slice<double> positions, rust::Slice<double> velocities) const;
  void set_joint_state(
      rust::Slice<const double> positions,
      rust::Slice<const double> velocities);
  void body_pose(std::size_t body, rust::Slice<double> out) const;
  void object_state(std::size_t i, rust::Slice<double> out) const;
  void set_object_state(std::size_t i, rust::Slice<const double> state);
  void object_coordinates(std::size_t i, rust::Slice<double> out) const;
  void set_object_coordinates(
      std::size_t i, rust::Slice<const double> values);
  void set_time(double t_s);
  std::size_t contact_count() const;

private:
  std::unique_ptr<WorldImpl> mImpl;
};

} // namespace rgdart
