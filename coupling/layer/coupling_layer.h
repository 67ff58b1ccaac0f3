/* SPDX-License-Identifier: GPL-3.0-or-later
   fiberform coupling layer: the MPI side of two-way coupling between fiberdem (the fibers) and
   fiberPimpleFoam -coupled (the fluid), both started under ONE mpirun in MPMD mode:

     mpirun -np A fiberdem -in in.coupled : -np 1 fiberPimpleFoam -coupled -case fluid
     LD_LIBRARY_PATH=<rebuilt libPstream> mpirun -np A fiberdem ... : -np B fiberPimpleFoam -coupled -parallel ...

   Plain MPI, C++17, no LIGGGHTS or OpenFOAM dependency. Full description: docs/coupling/layer.md.

   Start-up (start_world, collective on MPI_COMM_WORLD, the FIRST collective of both programs):
   MPI_Comm_split of MPI_COMM_WORLD by MPI_APPNUM (each program gets its own communicator), and, when
   the world holds two programs, an intercommunicator between them (MPI_Intercomm_create).

   Messages: only the leaders (rank 0 of each program) talk, over the intercommunicator. A message is
   a header (two int64: kind, payload bytes) and a payload of doubles (text for Error). Every blocking
   send and receive is an MPI_Test loop with a deadline: on time-out, or when the partner sends an
   Error message, the layer prints a message naming what it waited for on stderr and calls
   MPI_Abort(MPI_COMM_WORLD, kAbortStatus), which ends both programs with a non-zero status. */
#ifndef FIBERFORM_COUPLING_LAYER_H
#define FIBERFORM_COUPLING_LAYER_H

#include <mpi.h>

#include <cstdint>
#include <string>
#include <vector>

namespace fiberform::coupling {

/// Version of the message protocol below; both partners must agree (checked in the handshake).
inline constexpr int kProtocolVersion = 1;
/// Exit status of a run ended by the layer (time-out, partner error, handshake mismatch).
inline constexpr int kAbortStatus = 4;
/// Default deadline of one blocking exchange (s).
inline constexpr double kDefaultTimeout = 300.0;

enum class Role : int { Fibers = 1, Fluid = 2 };
const char *role_name(Role r);

enum class Kind : std::int64_t {
  Hello = 1,     // both ways: version, role, ranks
  Config = 2,    // fibers -> fluid: interval, dt, rho, mu, reaction
  Mesh = 3,      // fluid -> fibers: n, centres (3n), boxes (6n: lo xyz hi xyz), volumes (n)
  Velocity = 4,  // fluid -> fibers: cell velocities (3n, m/s)
  Reaction = 5,  // fibers -> fluid: force on the fluid per cell, interval mean (3n, N)
  Finish = 6,    // fibers -> fluid: the fiber run is over (no payload)
  Error = 7      // either way: text; the receiver prints it and aborts
};
const char *kind_name(Kind k);

/// The communicators of this program after start_world().
struct Session {
  bool started = false;
  MPI_Comm local = MPI_COMM_WORLD;  // this program's ranks (use instead of MPI_COMM_WORLD)
  MPI_Comm inter = MPI_COMM_NULL;   // to the partner program; MPI_COMM_NULL when running alone
  int appnum = 0;                   // MPI_APPNUM of this program (0 without MPMD)
  int partner_size = 0;             // ranks of the partner program (0 when alone)
};

/// Split MPI_COMM_WORLD by MPI_APPNUM and connect to the partner program if there is one.
/// Collective on MPI_COMM_WORLD: both programs must call it right after MPI_Init. More than two
/// programs under one mpirun is an error (message on stderr of world rank 0, MPI_Abort).
const Session &start_world();
/// The same for a program whose MPI_COMM_WORLD was already split by MPI_APPNUM elsewhere: a parallel
/// fiberPimpleFoam, whose rebuilt libPstream split it in UPstream::init (scripts/setup/
/// openfoam-pstream.sh). `local` is that split (this program's ranks); the rest of start_world()
/// (the check for two programs, the intercommunicator) runs unchanged. Collective on MPI_COMM_WORLD:
/// pairs with the partner's start_world().
const Session &join_world(MPI_Comm local);
/// The session made by start_world() or join_world() (started == false if neither was called).
const Session &session();

/// Messages between the leaders of the two programs, each blocking call bounded by a deadline.
/// Only rank 0 of the local communicator may construct and use a Channel.
class Channel {
 public:
  /// inter: the intercommunicator; self/partner: names used in messages ("fiberdem", "fiberPimpleFoam");
  /// timeout_s: deadline of each blocking send or receive (s, > 0).
  Channel(MPI_Comm inter, double timeout_s, std::string self, std::string partner);

  void send(Kind kind, const std::vector<double> &payload);
  void send(Kind kind) { send(kind, {}); }
  /// Receive the next message; it must be one of `expected` (else fail()). An Error message from the
  /// partner is printed and aborts. `what` names the wait in the time-out message.
  Kind recv(std::vector<double> &payload, std::initializer_list<Kind> expected, const char *what);

  /// Tell the partner (best effort, at most 1 s), print "<self>: coupling error: <message>" on stderr
  /// and MPI_Abort(MPI_COMM_WORLD, kAbortStatus).
  [[noreturn]] void fail(const std::string &message);

  double timeout() const { return timeout_; }

 private:
  void wait(MPI_Request *req, int n, const char *what);
  MPI_Comm inter_;
  double timeout_;
  std::string self_, partner_;
};

/// Print "<self>: coupling error: <message>" on stderr and MPI_Abort with kAbortStatus.
[[noreturn]] void abort_run(const std::string &self, const std::string &message);

// ---- handshake payloads (encoded as doubles; integers are exact up to 2^53) ----

struct Hello {
  int version = kProtocolVersion;
  Role role = Role::Fibers;
  int ranks = 1;
};
std::vector<double> encode(const Hello &h);
Hello decode_hello(const std::vector<double> &p);

struct Config {
  std::int64_t interval = 1;  // fiber steps per exchange
  double dt = 0.0;            // fiber time step (s); fluid step = interval * dt
  double rho = 0.0;           // fluid density used by the fibers' drag (kg/m3)
  double mu = 0.0;            // dynamic viscosity used by the fibers' drag (Pa s)
  bool reaction = true;       // false: the fibers send zero reaction (one-way through the layer)
};
std::vector<double> encode(const Config &c);
Config decode_config(const std::vector<double> &p);

struct Mesh {
  std::vector<double> centres;  // 3n (m)
  std::vector<double> boxes;    // 6n: lo x y z, hi x y z of each cell (m)
  std::vector<double> volumes;  // n (m3)
  std::size_t size() const { return volumes.size(); }
};
std::vector<double> encode(const Mesh &m);
Mesh decode_mesh(const std::vector<double> &p);

/// The whole handshake of one side over a Channel (leaders only). Both send Hello first and check
/// the partner's (version equal, roles complementary); then the fibers send Config and the fluid
/// sends Mesh. Mismatches fail() with a message naming both values.
void exchange_hello(Channel &ch, Role self, int ranks);

}  // namespace fiberform::coupling

#endif
