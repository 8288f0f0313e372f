// The C++ shim between realitygap's DART engine (Rust) and DART 6.12's C++
// API. It is built as a shared library of its own (see build.rs) whose C
// entry points (dart_capi.cc) the Rust side loads when it first needs
// DART. Kept thin: it builds skeletons, sets commands, steps
// and reads state; every decision (model planning, servo laws, checks) is
// on the Rust side. Every entry point that calls DART catches what DART
// throws and what it prints (see dart_shim.cc).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>

#include <string>
#include <string_view>

namespace rgdart {

// A view of `len` values at `ptr`, owned by the caller.
template <typename T>
class Slice
{
public:
  Slice(T* ptr, std::size_t len) : mPtr(ptr), mLen(len)
  {
  }
  std::size_t size() const
  {
    return mLen;
  }
  bool empty() const
  {
    return mLen == 0;
  }
  T* data() const
  {
    return mPtr;
  }
  T& operator[](std::size_t i) const
  {
    return mPtr[i];
  }
  T* begin() const
  {
    return mPtr;
  }
  T* end() const
  {
    return mPtr + mLen;
  }

private:
  T* mPtr;
  std::size_t mLen;
};

class World;

// What a step saw (see `World::advance`); the same layout as the Rust
// side's `ffi::StepReport`.
struct StepReport
{
  bool objects_finite;
  double max_speed;
  double max_spin;
  bool said;
};

std::string take_messages();
void say(std::string_view text);

std::unique_ptr<World> new_world(
    double timestep_s,
    Slice<const double> gravity,
    std::string_view detector,
    std::string_view lcp);

struct WorldImpl;

class World
{
public:
  explicit World(std::unique_ptr<WorldImpl> impl);
  ~World();

  std::size_t add_robot_body(
      std::string_view name,
      std::int64_t parent,
      std::uint8_t kind,
      Slice<const double> joint_pose,
      Slice<const double> axis,
      double mass_kg,
      Slice<const double> com,
      Slice<const double> inertia);
  void set_joint_limits(std::size_t joint, double lower, double upper);
  void set_joint_friction(std::size_t joint, double friction);
  void set_actuator(std::size_t joint, bool servo, double limit);
  void set_drives(
      Slice<const double> command,
      Slice<const double> damping,
      Slice<const double> stiffness,
      Slice<const double> rest);
  void add_shape(
      bool object,
      std::size_t body,
      std::uint8_t kind,
      Slice<const double> dims,
      Slice<const double> pose,
      double friction,
      double restitution);
  void add_mesh(
      std::size_t body,
      Slice<const double> vertices,
      Slice<const std::uint32_t> indices,
      Slice<const double> pose,
      double friction);
  std::size_t add_object(
      std::string_view name,
      double mass_kg,
      Slice<const double> inertia,
      Slice<const double> pose);
  void add_ground(double height, double friction, double restitution);
  void finish();
  void step();
  void step_raw(std::uint64_t n);
  StepReport advance(
      Slice<const double> command,
      Slice<const double> damping,
      Slice<const double> stiffness,
      Slice<const double> rest,
      Slice<double> positions,
      Slice<double> velocities);
  void joint_state(
      Slice<double> positions, Slice<double> velocities) const;
  void set_joint_state(
      Slice<const double> positions,
      Slice<const double> velocities);
  void body_pose(std::size_t body, Slice<double> out) const;
  void object_state(std::size_t i, Slice<double> out) const;
  void set_object_state(std::size_t i, Slice<const double> state);
  void object_coordinates(std::size_t i, Slice<double> out) const;
  void set_object_coordinates(
      std::size_t i, Slice<const double> values);
  void set_time(double t_s);
  std::size_t contact_count() const;

private:
  std::unique_ptr<WorldImpl> mImpl;
};

} // namespace rgdart
