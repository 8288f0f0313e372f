// The C++ shim over DART 6.12 (see dart_shim.h).
//
// Two rules hold for every entry point that calls DART:
// - what DART throws becomes a std::runtime_error naming the call, which
//   the C entry points (dart_capi.cc) hand to Rust as an error;
// - what DART prints (`dtmsg`/`dtdbg` to std::cout, `dtwarn`/`dterr` to
//   std::cerr) never reaches the process's streams: std::cout, std::cerr and
//   std::clog get (once per process) a forwarding buffer that, on a thread
//   inside a shim call, appends the text to that thread's buffer instead
//   (read with take_messages()); on any other thread it forwards unchanged.
//   The forwarding buffer keeps no put area, so no state is shared between
//   threads.

#include "dart_shim.h"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <assimp/material.h>
#include <assimp/mesh.h>
#include <assimp/scene.h>

#include <dart/collision/bullet/BulletCollisionDetector.hpp>
#include <dart/collision/dart/DARTCollisionDetector.hpp>
#include <dart/collision/fcl/FCLCollisionDetector.hpp>
#include <dart/collision/ode/OdeCollisionDetector.hpp>
#include <dart/common/Console.hpp>
#include <dart/config.hpp>
#include <dart/constraint/BoxedLcpConstraintSolver.hpp>
#include <dart/constraint/DantzigBoxedLcpSolver.hpp>
#include <dart/constraint/PgsBoxedLcpSolver.hpp>
#include <dart/dynamics/BodyNode.hpp>
#include <dart/dynamics/BoxShape.hpp>
#include <dart/dynamics/CapsuleShape.hpp>
#include <dart/dynamics/CylinderShape.hpp>
#include <dart/dynamics/FreeJoint.hpp>
#include <dart/dynamics/MeshShape.hpp>
#include <dart/dynamics/PrismaticJoint.hpp>
#include <dart/dynamics/RevoluteJoint.hpp>
#include <dart/dynamics/ShapeNode.hpp>
#include <dart/dynamics/Skeleton.hpp>
#include <dart/dynamics/SphereShape.hpp>
#include <dart/dynamics/WeldJoint.hpp>
#include <dart/simulation/World.hpp>

namespace rgdart {

namespace {

using dart::dynamics::BodyNode;
using dart::dynamics::Joint;
using dart::dynamics::SkeletonPtr;

thread_local int tCapturing = 0;
thread_local std::string tMessages;

// See the file comment.
class CaptureBuf : public std::streambuf
{
public:
  explicit CaptureBuf(std::streambuf* original) : mOriginal(original)
  {
  }

protected:
  int_type overflow(int_type c) override
  {
    if (traits_type::eq_int_type(c, traits_type::eof()))
      return traits_type::not_eof(c);
    if (tCapturing > 0)
    {
      tMessages.push_back(traits_type::to_char_type(c));
      return c;
    }
    return mOriginal ? mOriginal->sputc(traits_type::to_char_type(c))
                     : traits_type::eof();
  }

  std::streamsize xsputn(const char* s, std::streamsize n) override
  {
    if (tCapturing > 0)
    {
      tMessages.append(s, static_cast<std::size_t>(n));
      return n;
    }
    return mOriginal ? mOriginal->sputn(s, n) : 0;
  }

  int sync() override
  {
    if (tCapturing > 0 || !mOriginal)
      return 0;
    return mOriginal->pubsync();
  }

private:
  std::streambuf* mOriginal;
};

void installCapture()
{
  static std::once_flag once;
  std::call_once(once, [] {
    // Never freed: the streams may be flushed at exit, after statics die.
    std::cout.rdbuf(new CaptureBuf(std::cout.rdbuf()));
    std::cerr.rdbuf(new CaptureBuf(std::cerr.rdbuf()));
    std::clog.rdbuf(new CaptureBuf(std::clog.rdbuf()));
  });
}

// Captures DART's printing on this thread for its lifetime.
struct Capture
{
  Capture()
  {
    installCapture();
    ++tCapturing;
  }
  ~Capture()
  {
    --tCapturing;
  }
  Capture(const Capture&) = delete;
  Capture& operator=(const Capture&) = delete;
};

std::string said()
{
  if (tMessages.empty())
    return "";
  return " (DART said: " + tMessages + ")";
}

// Runs `f` with DART's printing captured; an exception becomes a
// std::runtime_error naming `what`, with what DART printed.
template <typename F>
auto guarded(const char* what, F&& f) -> decltype(f())
{
  Capture capture;
  try
  {
    return f();
  }
  catch (const std::exception& e)
  {
    throw std::runtime_error(std::string(what) + ": " + e.what() + said());
  }
  catch (...)
  {
    throw std::runtime_error(
        std::string(what) + ": an unknown C++ exception" + said());
  }
}

void need(bool ok, const std::string& message)
{
  if (!ok)
    throw std::invalid_argument(message);
}

void needLength(
    Slice<const double> s, std::size_t n, const char* what)
{
  need(
      s.size() == n,
      std::string(what) + " needs " + std::to_string(n) + " numbers, got "
          + std::to_string(s.size()));
  for (double v : s)
    need(std::isfinite(v), std::string(what) + " has a non-finite number");
}

Eigen::Vector3d vec3(Slice<const double> s, const char* what)
{
  needLength(s, 3, what);
  return Eigen::Vector3d(s[0], s[1], s[2]);
}

Eigen::Isometry3d pose(Slice<const double> s, const char* what)
{
  needLength(s, 7, what);
  Eigen::Quaterniond q(s[3], s[4], s[5], s[6]);
  need(q.norm() > 0.0, std::string(what) + " has a zero quaternion");
  q.normalize();
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = q.toRotationMatrix();
  t.translation() = Eigen::Vector3d(s[0], s[1], s[2]);
  return t;
}

void writePose(const Eigen::Isometry3d& t, Slice<double> out)
{
  if (out.size() < 7)
    return;
  const Eigen::Quaterniond q(t.linear());
  const Eigen::Vector3d p = t.translation();
  out[0] = p.x();
  out[1] = p.y();
  out[2] = p.z();
  out[3] = q.w();
  out[4] = q.x();
  out[5] = q.y();
  out[6] = q.z();
}

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kInfMax = std::numeric_limits<double>::max();

// Gives a joint of one degree of freedom the FORCE actuator with no bound
// of DART's own (the Rust side clamps every law to the force limit).
void forceActuator(Joint* joint)
{
  joint->setActuatorType(Joint::FORCE);
  joint->setForceLowerLimit(0, -kInf);
  joint->setForceUpperLimit(0, kInf);
  joint->setVelocityLowerLimit(0, -kInf);
  joint->setVelocityUpperLimit(0, kInf);
}

} // namespace

struct WorldImpl
{
  dart::simulation::WorldPtr world;
  SkeletonPtr robot;
  SkeletonPtr ground;
  std::vector<BodyNode*> bodies;
  std::vector<Joint*> joints;
  std::vector<SkeletonPtr> objects;
  /// The controlled joints' Coulomb friction torques as given (N m); what
  /// DART gets is scaled each step (see `World::set_drives`).
  std::vector<double> friction;
  /// Scratch of `World::set_drives`, kept so that a step allocates
  /// nothing: the friction DART gets, the mass matrix's factorisation and
  /// a unit vector with its solve.
  std::vector<double> scaled;
  Eigen::LDLT<Eigen::MatrixXd> mass;
  Eigen::VectorXd unit;
  Eigen::VectorXd column;
  bool finished = false;

  BodyNode* body(bool object, std::size_t i) const
  {
    if (object)
    {
      need(i < objects.size(), "no object " + std::to_string(i));
      return objects[i]->getBodyNode(0);
    }
    need(i < bodies.size(), "no robot body " + std::to_string(i));
    return bodies[i];
  }

  Joint* joint(std::size_t i) const
  {
    need(i < joints.size(), "no controlled joint " + std::to_string(i));
    return joints[i];
  }

  dart::dynamics::FreeJoint* freeJoint(std::size_t i) const
  {
    need(i < objects.size(), "no object " + std::to_string(i));
    return static_cast<dart::dynamics::FreeJoint*>(objects[i]->getJoint(0));
  }

  void attach(
      BodyNode* body,
      const dart::dynamics::ShapePtr& shape,
      const Eigen::Isometry3d& at,
      double friction,
      double restitution)
  {
    need(
        std::isfinite(friction) && friction >= 0.0,
        "friction must be >= 0 and finite");
    need(
        std::isfinite(restitution) && restitution >= 0.0,
        "restitution must be >= 0 and finite");
    auto* node = body->createShapeNodeWith<
        dart::dynamics::CollisionAspect,
        dart::dynamics::DynamicsAspect>(shape);
    node->setRelativeTransform(at);
    node->getDynamicsAspect()->setFrictionCoeff(friction);
    node->getDynamicsAspect()->setRestitutionCoeff(restitution);
  }
};

World::World(std::unique_ptr<WorldImpl> impl) : mImpl(std::move(impl))
{
}

World::~World()
{
  Capture capture;
  try
  {
    mImpl.reset();
  }
  catch (...)
  {
    // A destructor must not throw; DART's destructors do not.
  }
}

void say(std::string_view text)
{
  Capture capture;
  const std::string t(text);
  dtmsg << t << "\n";
  dtwarn << t << "\n";
  dterr << t << "\n";
  std::cout << t << std::endl;
  std::clog << t << std::endl;
}

std::string take_messages()
{
  std::string out(tMessages);
  tMessages.clear();
  return out;
}

std::unique_ptr<World> new_world(
    double timestep_s,
    Slice<const double> gravity,
    std::string_view detector,
    std::string_view lcp)
{
  return guarded("creating the DART world", [&] {
    need(
        std::isfinite(timestep_s) && timestep_s > 0.0,
        "the timestep must be positive and finite");
    const Eigen::Vector3d g = vec3(gravity, "gravity");
    auto impl = std::make_unique<WorldImpl>();
    impl->world = dart::simulation::World::create("realitygap");
    impl->world->setTimeStep(timestep_s);
    impl->world->setGravity(g);
    auto* solver = impl->world->getConstraintSolver();
    const std::string d(detector);
    if (d == "ode")
      solver->setCollisionDetector(
          dart::collision::OdeCollisionDetector::create());
    else if (d == "fcl")
      solver->setCollisionDetector(
          dart::collision::FCLCollisionDetector::create());
    else if (d == "bullet")
      solver->setCollisionDetector(
          dart::collision::BulletCollisionDetector::create());
    else if (d == "dart")
      solver->setCollisionDetector(
          dart::collision::DARTCollisionDetector::create());
    else
      throw std::invalid_argument("unknown collision detector " + d);
    auto* boxed
        = dynamic_cast<dart::constraint::BoxedLcpConstraintSolver*>(solver);
    need(boxed != nullptr, "DART's world has no boxed LCP constraint solver");
    const std::string l(lcp);
    if (l == "dantzig")
    {
      // DART's default: Dantzig, with PGS when Dantzig fails.
      boxed->setBoxedLcpSolver(
          std::make_shared<dart::constraint::DantzigBoxedLcpSolver>());
      boxed->setSecondaryBoxedLcpSolver(
          std::make_shared<dart::constraint::PgsBoxedLcpSolver>());
    }
    else if (l == "pgs")
    {
      boxed->setBoxedLcpSolver(
          std::make_shared<dart::constraint::PgsBoxedLcpSolver>());
      boxed->setSecondaryBoxedLcpSolver(nullptr);
    }
    else
      throw std::invalid_argument("unknown LCP solver " + l);
    impl->robot = dart::dynamics::Skeleton::create("robot");
    return std::make_unique<World>(std::move(impl));
  });
}

std::size_t World::add_robot_body(
    std::string_view name,
    std::int64_t parent,
    std::uint8_t kind,
    Slice<const double> joint_pose,
    Slice<const double> axis,
    double mass_kg,
    Slice<const double> com,
    Slice<const double> inertia)
{
  return guarded("adding a robot body", [&]() -> std::size_t {
    auto& m = *mImpl;
    need(!m.finished, "the world is finished");
    BodyNode* parentBody = nullptr;
    if (parent >= 0)
      parentBody = m.body(false, static_cast<std::size_t>(parent));
    need(
        std::isfinite(mass_kg) && mass_kg > 0.0,
        "the mass must be positive and finite");
    needLength(inertia, 9, "the inertia");
    Eigen::Matrix3d moment;
    moment << inertia[0], inertia[1], inertia[2], inertia[3], inertia[4],
        inertia[5], inertia[6], inertia[7], inertia[8];
    dart::dynamics::BodyNode::Properties body;
    body.mName = std::string(name);
    body.mInertia = dart::dynamics::Inertia(
        mass_kg, vec3(com, "the centre of mass"), moment);
    const Eigen::Isometry3d at = pose(joint_pose, "the joint pose");
    const std::string jointName = std::string(name) + "/joint";
    BodyNode* created = nullptr;
    Joint* joint = nullptr;
    switch (kind)
    {
      case 0:
      {
        dart::dynamics::WeldJoint::Properties j;
        j.mName = jointName;
        j.mT_ParentBodyToJoint = at;
        auto pair = m.robot->createJointAndBodyNodePair<
            dart::dynamics::WeldJoint>(parentBody, j, body);
        created = pair.second;
        break;
      }
      case 1:
      case 2:
      {
        Eigen::Vector3d a = vec3(axis, "the joint axis");
        need(a.norm() > 0.0, "the joint axis is zero");
        a.normalize();
        if (kind == 1)
        {
          dart::dynamics::RevoluteJoint::Properties j;
          j.mName = jointName;
          j.mT_ParentBodyToJoint = at;
          j.mAxis = a;
          auto pair = m.robot->createJointAndBodyNodePair<
              dart::dynamics::RevoluteJoint>(parentBody, j, body);
          created = pair.second;
          joint = pair.first;
        }
        else
        {
          dart::dynamics::PrismaticJoint::Properties j;
          j.mName = jointName;
          j.mT_ParentBodyToJoint = at;
          j.mAxis = a;
          auto pair = m.robot->createJointAndBodyNodePair<
              dart::dynamics::PrismaticJoint>(parentBody, j, body);
          created = pair.second;
          joint = pair.first;
        }
        break;
      }
      default:
        throw std::invalid_argument(
            "unknown joint kind " + std::to_string(kind));
    }
    if (joint)
    {
      forceActuator(joint);
      m.joints.push_back(joint);
    }
    m.bodies.push_back(created);
    return m.bodies.size() - 1;
  });
}

void World::set_joint_limits(std::size_t joint, double lower, double upper)
{
  guarded("setting joint limits", [&] {
    Joint* j = mImpl->joint(joint);
    need(!std::isnan(lower) && !std::isnan(upper), "a limit is NaN");
    need(lower <= upper, "the lower limit is above the upper one");
    j->setPositionLowerLimit(0, lower);
    j->setPositionUpperLimit(0, upper);
    j->setLimitEnforcement(std::isfinite(lower) || std::isfinite(upper));
  });
}

void World::set_joint_friction(std::size_t joint, double friction)
{
  guarded("setting joint friction", [&] {
    need(
        std::isfinite(friction) && friction >= 0.0,
        "the friction must be >= 0 and finite");
    mImpl->joint(joint)->setCoulombFriction(0, friction);
    auto& f = mImpl->friction;
    if (f.size() < mImpl->joints.size())
      f.resize(mImpl->joints.size(), 0.0);
    f[joint] = friction;
  });
}

void World::set_actuator(std::size_t joint, bool servo, double limit)
{
  guarded("setting an actuator", [&] {
    Joint* j = mImpl->joint(joint);
    if (servo)
    {
      need(!std::isnan(limit) && limit >= 0.0, "the force limit is NaN");
      j->setActuatorType(Joint::SERVO);
      j->setForceLowerLimit(0, -limit);
      j->setForceUpperLimit(0, limit);
      j->setVelocityLowerLimit(0, -kInf);
      j->setVelocityUpperLimit(0, kInf);
    }
    else
    {
      forceActuator(j);
    }
  });
}

void World::set_drives(
    Slice<const double> command,
    Slice<const double> damping,
    Slice<const double> stiffness,
    Slice<const double> rest)
{
  guarded("setting the drives", [&] {
    auto& m = *mImpl;
    const std::size_t n = m.joints.size();
    need(
        command.size() == n && damping.size() == n && stiffness.size() == n
            && rest.size() == n,
        "one drive per controlled joint is needed");
    // Joint friction beside the implicit damping. DART's friction is a
    // constraint of its impulse step, which sees the joint's inertia
    // without the implicit damping D (servo kv, joint damping, armature /
    // dt): over a step it then takes away (1 + dt D / I) times the torque
    // the damping gives back, and a sliding joint sees that much more
    // friction (breakaway too), more the larger the step. Giving DART the
    // friction divided by (1 + dt D (M^-1)_jj) makes the torque the one
    // asked for, at any step (the engine's README has the figures). M^-1
    // is inverted here from DART's mass matrix: DART's own inverse is
    // computed with unit joint forces, which on FORCE actuators overwrite
    // the commands.
    // (M^-1)_jj is column j of an LDLT solve with the j-th unit vector:
    // one factorisation per step, into storage kept from the last.
    auto& scaled = m.scaled;
    scaled.clear();
    const auto& f = m.friction;
    if (std::any_of(f.begin(), f.end(), [](double x) { return x > 0.0; }))
    {
      const double dt = m.world->getTimeStep();
      m.mass.compute(m.robot->getMassMatrix());
      const Eigen::Index dofs = m.mass.rows();
      if (m.unit.size() != dofs)
      {
        m.unit = Eigen::VectorXd::Zero(dofs);
        m.column.resize(dofs);
      }
      scaled.assign(n, 0.0);
      for (std::size_t i = 0; i < n && i < f.size(); ++i)
      {
        const double d = damping[i];
        if (!(f[i] > 0.0 && std::isfinite(d) && d >= 0.0))
        {
          scaled[i] = f[i];
          continue;
        }
        const auto k = static_cast<Eigen::Index>(m.joints[i]->getIndexInSkeleton(0));
        m.unit[k] = 1.0;
        m.column.noalias() = m.mass.solve(m.unit);
        m.unit[k] = 0.0;
        scaled[i] = f[i] / (1.0 + dt * d * m.column[k]);
      }
    }
    for (std::size_t i = 0; i < n; ++i)
    {
      // Finite, and gains >= 0 (NaN fails too).
      need(
          std::isfinite(command[i]) && std::isfinite(rest[i])
              && damping[i] >= 0.0 && damping[i] <= kInfMax
              && stiffness[i] >= 0.0 && stiffness[i] <= kInfMax,
          "a drive is not finite or has a negative gain");
      // Only what changed: DART's setters notify the skeleton, and within
      // a control period the laws' drives mostly stay the same (the world
      // steps without resetting the commands, see step()).
      Joint* j = m.joints[i];
      if (j->getCommand(0) != command[i])
        j->setCommand(0, command[i]);
      if (j->getDampingCoefficient(0) != damping[i])
        j->setDampingCoefficient(0, damping[i]);
      if (j->getSpringStiffness(0) != stiffness[i])
        j->setSpringStiffness(0, stiffness[i]);
      if (j->getRestPosition(0) != rest[i])
        j->setRestPosition(0, rest[i]);
      if (i < scaled.size() && j->getCoulombFriction(0) != scaled[i])
        j->setCoulombFriction(0, scaled[i]);
    }
  });
}

void World::add_shape(
    bool object,
    std::size_t body,
    std::uint8_t kind,
    Slice<const double> dims,
    Slice<const double> at,
    double friction,
    double restitution)
{
  guarded("adding a shape", [&] {
    auto& m = *mImpl;
    need(!m.finished, "the world is finished");
    BodyNode* b = m.body(object, body);
    for (double d : dims)
      need(std::isfinite(d) && d >= 0.0, "a shape size is negative or not finite");
    dart::dynamics::ShapePtr shape;
    switch (kind)
    {
      case 0:
        needLength(dims, 3, "a box");
        shape = std::make_shared<dart::dynamics::BoxShape>(
            Eigen::Vector3d(dims[0], dims[1], dims[2]));
        break;
      case 1:
        needLength(dims, 1, "a sphere");
        shape = std::make_shared<dart::dynamics::SphereShape>(dims[0]);
        break;
      case 2:
        needLength(dims, 2, "a cylinder");
        shape = std::make_shared<dart::dynamics::CylinderShape>(
            dims[0], dims[1]);
        break;
      case 3:
        needLength(dims, 2, "a capsule");
        shape = std::make_shared<dart::dynamics::CapsuleShape>(
            dims[0], dims[1]);
        break;
      default:
        throw std::invalid_argument(
            "unknown shape kind " + std::to_string(kind));
    }
    m.attach(b, shape, pose(at, "the shape pose"), friction, restitution);
  });
}

void World::add_mesh(
    std::size_t body,
    Slice<const double> vertices,
    Slice<const std::uint32_t> indices,
    Slice<const double> at,
    double friction)
{
  guarded("adding a mesh", [&] {
    auto& m = *mImpl;
    need(!m.finished, "the world is finished");
    BodyNode* b = m.body(false, body);
    need(
        !vertices.empty() && vertices.size() % 3 == 0,
        "mesh vertices must come in threes");
    need(
        !indices.empty() && indices.size() % 3 == 0,
        "mesh indices must come in threes");
    const std::size_t nv = vertices.size() / 3;
    const std::size_t nf = indices.size() / 3;
    for (double v : vertices)
      need(std::isfinite(v), "a mesh vertex is not finite");
    for (std::uint32_t i : indices)
      need(i < nv, "a mesh index names no vertex");
    // An aiScene of one mesh, allocated as assimp's own importer does:
    // MeshShape releases it with aiReleaseImport, which deletes a scene
    // that no importer owns (and with it its meshes, faces and nodes).
    //
    // DART 6.12's ODE collision detector (OdeMesh::fillArrays) copies the
    // mesh's per-vertex normals (mNormals, which it requires) and hands
    // them to ODE as per-TRIANGLE normals (dGeomTriMeshDataBuildDouble1):
    // ODE reads one normal per triangle from an array of one per vertex.
    // So the mesh gets at least as many vertices as triangles (padded with
    // copies of vertex 0, which change no bound) and vertex k's normal is
    // triangle k's normal: ODE then reads the right normals, in bounds.
    const std::size_t slots = std::max(nv, nf);
    auto* scene = new aiScene();
    auto* mesh = new aiMesh();
    scene->mNumMeshes = 1;
    scene->mMeshes = new aiMesh*[1]{mesh};
    scene->mNumMaterials = 1;
    scene->mMaterials = new aiMaterial*[1]{new aiMaterial()};
    scene->mRootNode = new aiNode();
    scene->mRootNode->mNumMeshes = 1;
    scene->mRootNode->mMeshes = new unsigned int[1]{0};
    mesh->mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
    mesh->mMaterialIndex = 0;
    mesh->mNumVertices = static_cast<unsigned int>(slots);
    mesh->mVertices = new aiVector3D[slots];
    mesh->mNormals = new aiVector3D[slots];
    for (std::size_t i = 0; i < slots; ++i)
    {
      const std::size_t k = i < nv ? i : 0;
      mesh->mVertices[i] = aiVector3D(
          static_cast<ai_real>(vertices[3 * k]),
          static_cast<ai_real>(vertices[3 * k + 1]),
          static_cast<ai_real>(vertices[3 * k + 2]));
      mesh->mNormals[i] = aiVector3D(0, 0, 1);
    }
    mesh->mNumFaces = static_cast<unsigned int>(nf);
    mesh->mFaces = new aiFace[nf];
    for (std::size_t f = 0; f < nf; ++f)
    {
      const unsigned int a = indices[3 * f];
      const unsigned int b = indices[3 * f + 1];
      const unsigned int c = indices[3 * f + 2];
      mesh->mFaces[f].mNumIndices = 3;
      mesh->mFaces[f].mIndices = new unsigned int[3]{a, b, c};
      const Eigen::Vector3d pa(
          vertices[3 * a], vertices[3 * a + 1], vertices[3 * a + 2]);
      const Eigen::Vector3d pb(
          vertices[3 * b], vertices[3 * b + 1], vertices[3 * b + 2]);
      const Eigen::Vector3d pc(
          vertices[3 * c], vertices[3 * c + 1], vertices[3 * c + 2]);
      Eigen::Vector3d n = (pb - pa).cross(pc - pa);
      if (n.norm() > 0.0)
        n.normalize();
      mesh->mNormals[f] = aiVector3D(
          static_cast<ai_real>(n.x()),
          static_cast<ai_real>(n.y()),
          static_cast<ai_real>(n.z()));
    }
    auto shape = std::make_shared<dart::dynamics::MeshShape>(
        Eigen::Vector3d::Ones(), scene);
    m.attach(b, shape, pose(at, "the mesh pose"), friction, 0.0);
  });
}

std::size_t World::add_object(
    std::string_view name,
    double mass_kg,
    Slice<const double> inertia,
    Slice<const double> at)
{
  return guarded("adding an object", [&]() -> std::size_t {
    auto& m = *mImpl;
    need(!m.finished, "the world is finished");
    need(
        std::isfinite(mass_kg) && mass_kg > 0.0,
        "the mass must be positive and finite");
    const Eigen::Vector3d principal = vec3(inertia, "the inertia");
    auto skel = dart::dynamics::Skeleton::create("object:" + std::string(name));
    dart::dynamics::FreeJoint::Properties j;
    j.mName = std::string(name) + "/joint";
    dart::dynamics::BodyNode::Properties body;
    body.mName = std::string(name);
    body.mInertia = dart::dynamics::Inertia(
        mass_kg, Eigen::Vector3d::Zero(), principal.asDiagonal());
    auto pair = skel->createJointAndBodyNodePair<dart::dynamics::FreeJoint>(
        nullptr, j, body);
    pair.first->setTransform(pose(at, "the object pose"));
    m.objects.push_back(skel);
    return m.objects.size() - 1;
  });
}

void World::add_ground(double height, double friction, double restitution)
{
  guarded("adding the ground", [&] {
    auto& m = *mImpl;
    need(!m.finished, "the world is finished");
    need(std::isfinite(height), "the ground height is not finite");
    m.ground = dart::dynamics::Skeleton::create("ground");
    dart::dynamics::WeldJoint::Properties j;
    j.mName = "ground/joint";
    j.mT_ParentBodyToJoint.translation() = Eigen::Vector3d(0, 0, height - 0.5);
    dart::dynamics::BodyNode::Properties body;
    body.mName = "ground";
    auto pair = m.ground->createJointAndBodyNodePair<dart::dynamics::WeldJoint>(
        nullptr, j, body);
    m.attach(
        pair.second,
        std::make_shared<dart::dynamics::BoxShape>(
            Eigen::Vector3d(20.0, 20.0, 1.0)),
        Eigen::Isometry3d::Identity(),
        friction,
        restitution);
  });
}

void World::finish()
{
  guarded("finishing the world", [&] {
    auto& m = *mImpl;
    need(!m.finished, "the world is finished already");
    m.robot->setSelfCollisionCheck(false);
    m.world->addSkeleton(m.robot);
    if (m.ground)
      m.world->addSkeleton(m.ground);
    for (auto& o : m.objects)
      m.world->addSkeleton(o);
    m.finished = true;
  });
}

void World::step()
{
  // Commands are not reset after the step: the Rust side sets every
  // joint's drive before every step (set_drives), and only what changed.
  guarded("stepping", [&] { mImpl->world->step(false); });
}

StepReport World::advance(
    Slice<const double> command,
    Slice<const double> damping,
    Slice<const double> stiffness,
    Slice<const double> rest,
    Slice<double> positions,
    Slice<double> velocities)
{
  set_drives(command, damping, stiffness, rest);
  const std::size_t before = tMessages.size();
  step();
  joint_state(positions, velocities);
  StepReport report{};
  report.objects_finite = true;
  for (std::size_t i = 0; i < mImpl->objects.size(); ++i)
  {
    // A free joint's coordinates: rotation vector and translation, then
    // angular and linear velocity in the body frame (norms as in the
    // world).
    const auto* j = mImpl->freeJoint(i);
    const auto& q = j->getPositionsStatic();
    const auto& v = j->getVelocitiesStatic();
    if (!q.allFinite() || !v.allFinite())
      report.objects_finite = false;
    report.max_spin = std::max(report.max_spin, v.head<3>().norm());
    report.max_speed = std::max(report.max_speed, v.tail<3>().norm());
  }
  report.said = tMessages.size() != before;
  return report;
}

void World::step_raw(std::uint64_t n)
{
  guarded("stepping", [&] {
    for (std::uint64_t i = 0; i < n; ++i)
      mImpl->world->step(false);
  });
}

void World::joint_state(
    Slice<double> positions, Slice<double> velocities) const
{
  const auto& joints = mImpl->joints;
  for (std::size_t i = 0; i < joints.size(); ++i)
  {
    if (i < positions.size())
      positions[i] = joints[i]->getPosition(0);
    if (i < velocities.size())
      velocities[i] = joints[i]->getVelocity(0);
  }
}

void World::set_joint_state(
    Slice<const double> positions, Slice<const double> velocities)
{
  guarded("setting the joint state", [&] {
    const auto& joints = mImpl->joints;
    needLength(positions, joints.size(), "the joint positions");
    needLength(velocities, joints.size(), "the joint velocities");
    for (std::size_t i = 0; i < joints.size(); ++i)
    {
      joints[i]->setPosition(0, positions[i]);
      joints[i]->setVelocity(0, velocities[i]);
    }
  });
}

void World::body_pose(std::size_t body, Slice<double> out) const
{
  if (body < mImpl->bodies.size())
    writePose(mImpl->bodies[body]->getWorldTransform(), out);
}

void World::object_state(std::size_t i, Slice<double> out) const
{
  if (i >= mImpl->objects.size() || out.size() < 13)
    return;
  BodyNode* b = mImpl->objects[i]->getBodyNode(0);
  writePose(b->getWorldTransform(), out);
  const Eigen::Vector3d v = b->getLinearVelocity();
  const Eigen::Vector3d w = b->getAngularVelocity();
  for (int k = 0; k < 3; ++k)
  {
    out[7 + k] = v[k];
    out[10 + k] = w[k];
  }
}

void World::set_object_state(std::size_t i, Slice<const double> state)
{
  guarded("setting an object's state", [&] {
    auto* j = mImpl->freeJoint(i);
    needLength(state, 13, "the object state");
    const double* s = state.data();
    j->setTransform(pose(Slice<const double>(s, 7), "the object pose"));
    j->setLinearVelocity(Eigen::Vector3d(s[7], s[8], s[9]));
    j->setAngularVelocity(Eigen::Vector3d(s[10], s[11], s[12]));
  });
}

void World::object_coordinates(std::size_t i, Slice<double> out) const
{
  if (i >= mImpl->objects.size() || out.size() < 12)
    return;
  const auto& skel = mImpl->objects[i];
  const Eigen::VectorXd q = skel->getPositions();
  const Eigen::VectorXd v = skel->getVelocities();
  for (int k = 0; k < 6; ++k)
  {
    out[k] = q[k];
    out[6 + k] = v[k];
  }
}

void World::set_object_coordinates(
    std::size_t i, Slice<const double> values)
{
  guarded("setting an object's coordinates", [&] {
    need(i < mImpl->objects.size(), "no object " + std::to_string(i));
    needLength(values, 12, "the object coordinates");
    const auto& skel = mImpl->objects[i];
    Eigen::Vector6d q;
    Eigen::Vector6d v;
    for (int k = 0; k < 6; ++k)
    {
      q[k] = values[k];
      v[k] = values[6 + k];
    }
    skel->setPositions(q);
    skel->setVelocities(v);
  });
}

void World::set_time(double t_s)
{
  mImpl->world->setTime(t_s);
}

std::size_t World::contact_count() const
{
  return mImpl->world->getLastCollisionResult().getNumContacts();
}

} // namespace rgdart
