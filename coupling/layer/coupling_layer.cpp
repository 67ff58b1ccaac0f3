/* SPDX-License-Identifier: GPL-3.0-or-later
   fiberform coupling layer: see coupling_layer.h and docs/coupling/layer.md. */
#include "coupling_layer.h"
#include "patient_wait.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

namespace fiberform::coupling {
namespace {

constexpr int kTagHeader = 7101;
constexpr int kTagPayload = 7102;
constexpr int kTagIntercomm = 7100;

Session g_session;

}  // namespace

const char *role_name(Role r) { return r == Role::Fibers ? "fibers (fiberdem)" : "fluid (fiberPimpleFoam)"; }

const char *kind_name(Kind k) {
  switch (k) {
    case Kind::Hello: return "Hello";
    case Kind::Config: return "Config";
    case Kind::Mesh: return "Mesh";
    case Kind::Velocity: return "Velocity";
    case Kind::Reaction: return "Reaction";
    case Kind::Finish: return "Finish";
    case Kind::Error: return "Error";
  }
  return "unknown";
}

void abort_run(const std::string &self, const std::string &message) {
  std::fprintf(stderr, "%s: coupling error: %s\n", self.c_str(), message.c_str());
  std::fflush(stderr);
  std::fflush(stdout);
  MPI_Abort(MPI_COMM_WORLD, kAbortStatus);
  std::abort();  // not reached
}

const Session &session() { return g_session; }

namespace {

int world_appnum() {
  int flag = 0;
  int *app = nullptr;
  MPI_Comm_get_attr(MPI_COMM_WORLD, MPI_APPNUM, &app, &flag);
  return flag && app ? *app : 0;
}

// Everything after the split: with more than one program in the world, check there are exactly two
// and build the intercommunicator (collective on MPI_COMM_WORLD).
const Session &connect(MPI_Comm local, int appnum) {
  int wrank = 0, wsize = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &wrank);
  MPI_Comm_size(MPI_COMM_WORLD, &wsize);
  Session s;
  s.started = true;
  s.appnum = appnum;
  s.local = local;
  int lsize = 1;
  MPI_Comm_size(s.local, &lsize);
  if (lsize < wsize) {  // every rank sees the same answer: more than one program in the world
    std::vector<int> apps(static_cast<std::size_t>(wsize));
    MPI_Allgather(&appnum, 1, MPI_INT, apps.data(), 1, MPI_INT, MPI_COMM_WORLD);
    int leader = -1, napps = 0;
    std::vector<int> seen;
    for (int r = 0; r < wsize; ++r) {
      if (std::find(seen.begin(), seen.end(), apps[static_cast<std::size_t>(r)]) == seen.end())
        seen.push_back(apps[static_cast<std::size_t>(r)]);
      if (leader < 0 && apps[static_cast<std::size_t>(r)] != appnum) leader = r;
    }
    napps = static_cast<int>(seen.size());
    if (napps != 2) {
      if (wrank == 0)
        std::fprintf(stderr,
                     "fiberform coupling: %d programs under one mpirun; a coupled run has exactly two "
                     "(mpirun -np A fiberdem ... : -np 1 fiberPimpleFoam -coupled ...)\n",
                     napps);
      std::fflush(stderr);
      MPI_Abort(MPI_COMM_WORLD, kAbortStatus);
    }
    MPI_Intercomm_create(s.local, 0, MPI_COMM_WORLD, leader, kTagIntercomm, &s.inter);
    MPI_Comm_remote_size(s.inter, &s.partner_size);
  }
  g_session = s;
  return g_session;
}

}  // namespace

const Session &start_world() {
  if (g_session.started) return g_session;
  int wrank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &wrank);
  const int appnum = world_appnum();
  MPI_Comm local = MPI_COMM_NULL;
  MPI_Comm_split(MPI_COMM_WORLD, appnum, wrank, &local);
  return connect(local, appnum);
}

const Session &join_world(MPI_Comm local) {
  if (g_session.started) return g_session;
  return connect(local, world_appnum());
}

Channel::Channel(MPI_Comm inter, double timeout_s, std::string self, std::string partner)
    : inter_(inter), timeout_(timeout_s), self_(std::move(self)), partner_(std::move(partner)) {}

void Channel::wait(MPI_Request *req, int n, const char *what) {
  Patience how;  // polls every 200 us
  how.deadline_s = clock_s() + timeout_;
  if (patient_wait(req, n, how)) return;
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "no answer from %s within the coupling timeout of %g s while %s (the partner "
                "crashed, hangs, is not a coupled %s, or one exchange interval takes longer than "
                "the timeout: raise `timeout`)",
                partner_.c_str(), timeout_, what, partner_.c_str());
  abort_run(self_, buf);
}

void Channel::send(Kind kind, const std::vector<double> &payload) {
  std::int64_t header[2] = {static_cast<std::int64_t>(kind),
                            static_cast<std::int64_t>(payload.size() * sizeof(double))};
  MPI_Request req[2];
  int n = 1;
  MPI_Isend(header, 2, MPI_INT64_T, 0, kTagHeader, inter_, &req[0]);
  if (!payload.empty()) {
    MPI_Isend(payload.data(), static_cast<int>(payload.size()), MPI_DOUBLE, 0, kTagPayload, inter_,
              &req[1]);
    n = 2;
  }
  const std::string what = std::string("sending ") + kind_name(kind);
  wait(req, n, what.c_str());
}

Kind Channel::recv(std::vector<double> &payload, std::initializer_list<Kind> expected, const char *what) {
  std::int64_t header[2] = {0, 0};
  MPI_Request req;
  MPI_Irecv(header, 2, MPI_INT64_T, 0, kTagHeader, inter_, &req);
  wait(&req, 1, what);
  const Kind kind = static_cast<Kind>(header[0]);
  const std::int64_t bytes = header[1];
  if (bytes < 0 || bytes % static_cast<std::int64_t>(sizeof(double)) != 0)
    fail("malformed message header from " + partner_);
  payload.assign(static_cast<std::size_t>(bytes) / sizeof(double), 0.0);
  if (bytes > 0) {
    MPI_Irecv(payload.data(), static_cast<int>(payload.size()), MPI_DOUBLE, 0, kTagPayload, inter_, &req);
    wait(&req, 1, what);
  }
  if (kind == Kind::Error) {
    std::string text;
    for (double c : payload) text.push_back(static_cast<char>(static_cast<int>(c)));
    abort_run(self_, partner_ + " reports: " + text);
  }
  if (std::find(expected.begin(), expected.end(), kind) == expected.end()) {
    std::string want;
    for (Kind k : expected) want += std::string(want.empty() ? "" : " or ") + kind_name(k);
    fail(std::string("protocol error while ") + what + ": expected " + want + " from " + partner_ +
         ", got " + kind_name(kind) + " (" + std::to_string(header[0]) + ")");
  }
  return kind;
}

void Channel::fail(const std::string &message) {
  std::vector<double> text;
  for (char c : message) text.push_back(static_cast<double>(static_cast<unsigned char>(c)));
  std::int64_t header[2] = {static_cast<std::int64_t>(Kind::Error),
                            static_cast<std::int64_t>(text.size() * sizeof(double))};
  MPI_Request req[2];
  MPI_Isend(header, 2, MPI_INT64_T, 0, kTagHeader, inter_, &req[0]);
  MPI_Isend(text.data(), static_cast<int>(text.size()), MPI_DOUBLE, 0, kTagPayload, inter_, &req[1]);
  Patience how;  // polls every 200 us, at most 1 s (the message is printed here anyway)
  how.deadline_s = clock_s() + std::min(1.0, timeout_);
  patient_wait(req, 2, how);
  abort_run(self_, message);
}

// ---- payloads ----

std::vector<double> encode(const Hello &h) {
  return {static_cast<double>(h.version), static_cast<double>(static_cast<int>(h.role)),
          static_cast<double>(h.ranks)};
}

Hello decode_hello(const std::vector<double> &p) {
  Hello h;
  h.version = p.size() > 0 ? static_cast<int>(p[0]) : -1;
  h.role = p.size() > 1 ? static_cast<Role>(static_cast<int>(p[1])) : Role::Fibers;
  h.ranks = p.size() > 2 ? static_cast<int>(p[2]) : 0;
  return h;
}

std::vector<double> encode(const Config &c) {
  return {static_cast<double>(c.interval), c.dt, c.rho, c.mu, c.reaction ? 1.0 : 0.0};
}

Config decode_config(const std::vector<double> &p) {
  Config c;
  if (p.size() != 5) return Config{0, 0.0, 0.0, 0.0, false};
  c.interval = static_cast<std::int64_t>(p[0]);
  c.dt = p[1];
  c.rho = p[2];
  c.mu = p[3];
  c.reaction = p[4] != 0.0;
  return c;
}

std::vector<double> encode(const Mesh &m) {
  std::vector<double> p;
  p.reserve(1 + 10 * m.size());
  p.push_back(static_cast<double>(m.size()));
  p.insert(p.end(), m.centres.begin(), m.centres.end());
  p.insert(p.end(), m.boxes.begin(), m.boxes.end());
  p.insert(p.end(), m.volumes.begin(), m.volumes.end());
  return p;
}

Mesh decode_mesh(const std::vector<double> &p) {
  Mesh m;
  if (p.empty()) return m;
  const auto n = static_cast<std::size_t>(p[0]);
  if (p.size() != 1 + 10 * n) return m;
  auto it = p.begin() + 1;
  m.centres.assign(it, it + static_cast<std::ptrdiff_t>(3 * n));
  it += static_cast<std::ptrdiff_t>(3 * n);
  m.boxes.assign(it, it + static_cast<std::ptrdiff_t>(6 * n));
  it += static_cast<std::ptrdiff_t>(6 * n);
  m.volumes.assign(it, it + static_cast<std::ptrdiff_t>(n));
  return m;
}

void exchange_hello(Channel &ch, Role self, int ranks) {
  ch.send(Kind::Hello, encode(Hello{kProtocolVersion, self, ranks}));
  std::vector<double> p;
  ch.recv(p, {Kind::Hello}, "waiting for the partner's Hello (start-up handshake)");
  const Hello h = decode_hello(p);
  if (h.version != kProtocolVersion)
    ch.fail("protocol version mismatch: this side speaks " + std::to_string(kProtocolVersion) +
            ", the partner " + std::to_string(h.version) + " (rebuild both from the same source)");
  const Role want = self == Role::Fibers ? Role::Fluid : Role::Fibers;
  if (h.role != want)
    ch.fail(std::string("the partner is not the ") + role_name(want) + " (role " +
            std::to_string(static_cast<int>(h.role)) + ")");
}

}  // namespace fiberform::coupling
