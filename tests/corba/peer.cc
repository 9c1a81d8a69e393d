// peer.cc: the C++ omniORB peer of tests/test_corba_*.py, built with g++ from omniidl's stubs
// of Peer.idl (and of CosNaming / CosEventChannelAdmin, from omniORB's own IDL).
//
//   peer server NAME [ORB options]      serve Peer::Echo, bound in the naming service as NAME
//                                       (a/b/c: contexts created when missing); prints
//                                       "READY <IOR>", serves until stdin closes
//   peer client NAME [ORB options]      resolve NAME, call every operation, check the results;
//                                       prints "PASS what" / "FAIL what: why", exit 1 on a FAIL
//   peer push CHANNEL N [ORB options]   push N anys (Peer::Point {i, 2i}) into the event channel
//                                       bound as CHANNEL, then a Peer::Nested
//   peer consume CHANNEL N [ORB opts]   receive N events from CHANNEL, print "EVENT ..." each
//   peer bench NAME N [ORB options]     N calls of nothing() and echo_text(); prints
//                                       "P50 <us> <us>" (NAME may be an IOR or a URL too)

#include <Peer.hh>
#include <omniORB4/Naming.hh>
#include <CosEventChannelAdmin.hh>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

static int failures = 0;

static void check(bool ok, const std::string& what, const std::string& why = "")
{
  if (ok)
    std::cout << "PASS " << what << std::endl;
  else {
    std::cout << "FAIL " << what << (why.empty() ? "" : ": ") << why << std::endl;
    ++failures;
  }
}

static CosNaming::Name to_name(const std::string& path)
{
  CosNaming::Name name;
  std::stringstream in(path);
  std::string part;
  while (std::getline(in, part, '/')) {
    CORBA::ULong i = name.length();
    name.length(i + 1);
    name[i].id = CORBA::string_dup(part.c_str());
    name[i].kind = CORBA::string_dup("");
  }
  return name;
}

static CosNaming::NamingContext_ptr root(CORBA::ORB_ptr orb)
{
  CORBA::Object_var obj = orb->resolve_initial_references("NameService");
  return CosNaming::NamingContext::_narrow(obj);
}

static void bind_path(CosNaming::NamingContext_ptr ctx, const std::string& path, CORBA::Object_ptr obj)
{
  CosNaming::Name name = to_name(path);
  CosNaming::NamingContext_var current = CosNaming::NamingContext::_duplicate(ctx);
  for (CORBA::ULong i = 0; i + 1 < name.length(); ++i) {
    CosNaming::Name one;
    one.length(1);
    one[0] = name[i];
    try {
      CORBA::Object_var sub = current->resolve(one);
      current = CosNaming::NamingContext::_narrow(sub);
    }
    catch (CosNaming::NamingContext::NotFound&) {
      current = current->bind_new_context(one);
    }
  }
  CosNaming::Name last;
  last.length(1);
  last[0] = name[name.length() - 1];
  current->rebind(last, obj);
}

// ---- the servants -------------------------------------------------------------------------

class EchoImpl : public POA_Peer::Echo
{
public:
  EchoImpl() : fired_(0), counter_(0) {}
  Peer::Prims echo_prims(const Peer::Prims& p) { return p; }
  Peer::Nested* echo_nested(const Peer::Nested& n) { return new Peer::Nested(n); }
  Peer::NestedSeq* echo_nesteds(const Peer::NestedSeq& n) { return new Peer::NestedSeq(n); }
  char* echo_text(const char* s) { return CORBA::string_dup(s); }
  Peer::LongSeq* echo_longs(const Peer::LongSeq& s) { return new Peer::LongSeq(s); }
  Peer::DoubleSeq* echo_doubles(const Peer::DoubleSeq& d) { return new Peer::DoubleSeq(d); }
  Peer::Octets* echo_octets(const Peer::Octets& o) { return new Peer::Octets(o); }
  Peer::StringSeq* echo_strings(const Peer::StringSeq& s) { return new Peer::StringSeq(s); }
  Peer::Shape* echo_shape(const Peer::Shape& s) { return new Peer::Shape(s); }
  Peer::Pick echo_pick(const Peer::Pick& p) { return p; }
  Peer::Color echo_color(Peer::Color c) { return c; }
  CORBA::Double mixed(CORBA::Long a, CORBA::Long& twice, CORBA::String_out text, Peer::Point& p,
                      Peer::Matrix m)
  {
    twice = 2 * a;
    std::ostringstream s;
    s << "a=" << a;
    text = CORBA::string_dup(s.str().c_str());
    p.x += 1;
    p.y += 1;
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 3; ++j)
        m[i][j] *= 10;
    return a / 4.0;
  }
  void nothing() {}
  void raise_it(CORBA::Long which)
  {
    if (which == 0) throw Peer::Failed("bad", 42, 2.5);
    if (which == 1) throw Peer::Empty();
    if (which == 2) throw CORBA::BAD_PARAM(7, CORBA::COMPLETED_NO);
    if (which == 3) throw CORBA::NO_PERMISSION(5, CORBA::COMPLETED_YES);
  }
  void fire(CORBA::Long v) { fired_ += v; }
  CORBA::Long fired() { return fired_; }
  Peer::Echo_ptr myself() { return _this(); }
  char* call_back(Peer::Callback_ptr cb, const char* what) { return cb->notify(what); }
  CORBA::Object_ptr echo_object(CORBA::Object_ptr o) { return CORBA::Object::_duplicate(o); }
  Peer::CallbackSeq* echo_callbacks(const Peer::CallbackSeq& cbs) { return new Peer::CallbackSeq(cbs); }
  void swap_echo(Peer::Echo_ptr& e)
  {
    CORBA::release(e);
    e = _this();
  }
  CORBA::Long counter() { return counter_; }
  void counter(CORBA::Long c) { counter_ = c; }
  char* label() { return CORBA::string_dup("cpp"); }

private:
  CORBA::Long fired_;
  CORBA::Long counter_;
};

class CallbackImpl : public POA_Peer::Callback
{
public:
  char* notify(const char* what)
  {
    std::string s = std::string("cpp got ") + what;
    return CORBA::string_dup(s.c_str());
  }
};

// ---- modes ----------------------------------------------------------------------------------

static int serve(CORBA::ORB_ptr orb, const std::string& name)
{
  CORBA::Object_var obj = orb->resolve_initial_references("RootPOA");
  PortableServer::POA_var root_poa = PortableServer::POA::_narrow(obj);
  PortableServer::POAManager_var manager = root_poa->the_POAManager();
  CORBA::PolicyList policies;
  policies.length(2);
  policies[0] = root_poa->create_lifespan_policy(PortableServer::PERSISTENT);
  policies[1] = root_poa->create_id_assignment_policy(PortableServer::USER_ID);
  PortableServer::POA_var poa = root_poa->create_POA("peer", manager, policies);
  EchoImpl* echo = new EchoImpl;
  PortableServer::ObjectId_var id = PortableServer::string_to_ObjectId("Echo");
  poa->activate_object_with_id(id, echo);
  CORBA::Object_var ref = poa->id_to_reference(id);
  manager->activate();
  if (!name.empty()) {
    CosNaming::NamingContext_var ctx = root(orb);
    bind_path(ctx, name, ref);
  }
  CORBA::String_var ior = orb->object_to_string(ref);
  std::cout << "READY " << ior << std::endl;
  std::string line;
  while (std::getline(std::cin, line)) {
  }
  orb->shutdown(1);
  return 0;
}

static Peer::Nested make_nested(int i)
{
  Peer::Nested n;
  std::ostringstream s;
  s << "nested-" << i;
  n.name = CORBA::string_dup(s.str().c_str());
  n.p.x = i;
  n.p.y = -i;
  n.points.length(2);
  n.points[0].x = 1; n.points[0].y = 2;
  n.points[1].x = 3; n.points[1].y = 4;
  n.outline.value(0.5);
  n.outline._d(4);
  n.hue = Peer::BLUE;
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 3; ++b)
      n.m[a][b] = a * 3 + b;
  n.longs.length(3);
  n.longs[0] = -1; n.longs[1] = 0; n.longs[2] = 2147483647;
  n.colors.length(2);
  n.colors[0] = Peer::GREEN; n.colors[1] = Peer::RED;
  n.flags.length(3);
  n.flags[0] = 1; n.flags[1] = 0; n.flags[2] = 1;
  n.tag = CORBA::string_dup("tag");
  n.last = 1e300;
  return n;
}

static bool same(const Peer::Nested& a, const Peer::Nested& b)
{
  bool ok = std::strcmp(a.name, b.name) == 0 && a.p.x == b.p.x && a.p.y == b.p.y &&
            a.points.length() == b.points.length() && a.hue == b.hue &&
            a.longs.length() == b.longs.length() && a.colors.length() == b.colors.length() &&
            a.flags.length() == b.flags.length() && std::strcmp(a.tag, b.tag) == 0 &&
            a.last == b.last && a.outline._d() == b.outline._d();
  for (CORBA::ULong i = 0; ok && i < a.points.length(); ++i)
    ok = a.points[i].x == b.points[i].x && a.points[i].y == b.points[i].y;
  for (CORBA::ULong i = 0; ok && i < a.longs.length(); ++i) ok = a.longs[i] == b.longs[i];
  for (CORBA::ULong i = 0; ok && i < a.colors.length(); ++i) ok = a.colors[i] == b.colors[i];
  for (CORBA::ULong i = 0; ok && i < a.flags.length(); ++i) ok = a.flags[i] == b.flags[i];
  for (int x = 0; ok && x < 2; ++x)
    for (int y = 0; ok && y < 3; ++y) ok = a.m[x][y] == b.m[x][y];
  if (ok && (a.outline._d() == 3 || a.outline._d() == 4)) ok = a.outline.value() == b.outline.value();
  return ok;
}

static Peer::Echo_ptr resolve_echo(CORBA::ORB_ptr orb, const std::string& name)
{
  CORBA::Object_var obj;
  if (name.find(':') != std::string::npos)  // an IOR or a corbaloc/corbaname URL
    obj = orb->string_to_object(name.c_str());
  else {
    CosNaming::NamingContext_var ctx = root(orb);
    obj = ctx->resolve(to_name(name));
  }
  return Peer::Echo::_narrow(obj);
}

static void activate_poa(CORBA::ORB_ptr orb)
{
  CORBA::Object_var obj = orb->resolve_initial_references("RootPOA");
  PortableServer::POA_var poa = PortableServer::POA::_narrow(obj);
  PortableServer::POAManager_var manager = poa->the_POAManager();
  manager->activate();
}

static int client(CORBA::ORB_ptr orb, const std::string& name)
{
  activate_poa(orb);
  Peer::Echo_var echo = resolve_echo(orb, name);
  check(!CORBA::is_nil(echo), "narrow");

  Peer::Prims p;
  p.s = -32768; p.us = 65535; p.l = -2147483647 - 1; p.ul = 4294967295U;
  p.ll = -9223372036854775807LL - 1; p.ull = 18446744073709551615ULL;
  p.f = 1.5f; p.d = -2.25; p.b = 1; p.c = 'z'; p.o = 255;
  Peer::Prims q = echo->echo_prims(p);
  check(q.s == p.s && q.us == p.us && q.l == p.l && q.ul == p.ul && q.ll == p.ll &&
        q.ull == p.ull && q.f == p.f && q.d == p.d && q.b == p.b && q.c == p.c && q.o == p.o,
        "prims");

  Peer::Nested n = make_nested(7);
  Peer::Nested_var m = echo->echo_nested(n);
  check(same(n, m.in()), "nested");

  Peer::NestedSeq ns;
  ns.length(3);
  for (int i = 0; i < 3; ++i) ns[i] = make_nested(i);
  ns[1].outline.name("circle");
  ns[2].outline.where(n.p);
  Peer::NestedSeq_var ms = echo->echo_nesteds(ns);
  bool ok = ms->length() == 3;
  for (int i = 0; ok && i < 3; ++i) ok = same(ns[i], ms[i]);
  check(ok && std::strcmp(ms[1].outline.name(), "circle") == 0 && ms[2].outline.where().x == 7,
        "nesteds");

  CORBA::String_var t = echo->echo_text("h\xc3\xa9llo, w\xc3\xb6rld");
  check(std::strcmp(t, "h\xc3\xa9llo, w\xc3\xb6rld") == 0, "text", std::string(t));
  CORBA::String_var empty = echo->echo_text("");
  check(std::strcmp(empty, "") == 0, "empty text");

  Peer::LongSeq ls;
  ls.length(1000);
  for (CORBA::ULong i = 0; i < 1000; ++i) ls[i] = i * 3 - 500;
  Peer::LongSeq_var lr = echo->echo_longs(ls);
  ok = lr->length() == 1000;
  for (CORBA::ULong i = 0; ok && i < 1000; ++i) ok = lr[i] == ls[i];
  check(ok, "longs");

  Peer::DoubleSeq ds;
  ds.length(5);
  for (CORBA::ULong i = 0; i < 5; ++i) ds[i] = i / 3.0;
  Peer::DoubleSeq_var dr = echo->echo_doubles(ds);
  ok = dr->length() == 5;
  for (CORBA::ULong i = 0; ok && i < 5; ++i) ok = dr[i] == ds[i];
  check(ok, "doubles");

  Peer::Octets os;
  os.length(256);
  for (CORBA::ULong i = 0; i < 256; ++i) os[i] = (CORBA::Octet)i;
  Peer::Octets_var orr = echo->echo_octets(os);
  ok = orr->length() == 256;
  for (CORBA::ULong i = 0; ok && i < 256; ++i) ok = orr[i] == os[i];
  check(ok, "octets");

  Peer::StringSeq ss;
  ss.length(3);
  ss[0] = CORBA::string_dup("a"); ss[1] = CORBA::string_dup(""); ss[2] = CORBA::string_dup("ccc");
  Peer::StringSeq_var sr = echo->echo_strings(ss);
  check(sr->length() == 3 && std::strcmp(sr[0], "a") == 0 && std::strcmp(sr[1], "") == 0 &&
        std::strcmp(sr[2], "ccc") == 0, "strings");

  Peer::Shape sh;
  sh.count(5);
  Peer::Shape_var shr = echo->echo_shape(sh);
  check(shr->_d() == 1 && shr->count() == 5, "shape count");
  sh.value(1.25);
  sh._d(3);
  shr = echo->echo_shape(sh);
  check(shr->_d() == 3 && shr->value() == 1.25, "shape value (second label)");
  Peer::Point where; where.x = 9; where.y = 8;
  sh.where(where);
  sh._d(99);
  shr = echo->echo_shape(sh);
  check(shr->_d() == 99 && shr->where().x == 9 && shr->where().y == 8, "shape default");

  Peer::Pick pk;
  pk.g(where);
  Peer::Pick pkr = echo->echo_pick(pk);
  check(pkr._d() == Peer::GREEN && pkr.g().y == 8, "pick");
  pk._default();
  pk._d(Peer::BLUE);
  pkr = echo->echo_pick(pk);
  check(pkr._d() == Peer::BLUE, "pick without branch");

  check(echo->echo_color(Peer::GREEN) == Peer::GREEN, "color");

  CORBA::Long twice = 0;
  CORBA::String_var text;
  Peer::Point pt; pt.x = 1; pt.y = 2;
  Peer::Matrix mx;
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 3; ++b) mx[a][b] = a + b;
  CORBA::Double r = echo->mixed(6, twice, text.out(), pt, mx);
  check(r == 1.5 && twice == 12 && std::strcmp(text, "a=6") == 0 && pt.x == 2 && pt.y == 3 &&
        mx[1][2] == 30, "mixed");

  echo->nothing();
  check(true, "nothing");

  try {
    echo->raise_it(0);
    check(false, "user exception", "nothing raised");
  }
  catch (Peer::Failed& f) {
    check(std::strcmp(f.reason, "bad") == 0 && f.code == 42 && f.when == 2.5, "user exception");
  }
  try {
    echo->raise_it(1);
    check(false, "empty exception", "nothing raised");
  }
  catch (Peer::Empty&) {
    check(true, "empty exception");
  }
  try {
    echo->raise_it(2);
    check(false, "system exception", "nothing raised");
  }
  catch (CORBA::BAD_PARAM& e) {
    check(e.minor() == 7 && e.completed() == CORBA::COMPLETED_NO, "system exception");
  }
  try {
    echo->raise_it(3);
    check(false, "other system exception", "nothing raised");
  }
  catch (CORBA::NO_PERMISSION& e) {
    check(e.minor() == 5 && e.completed() == CORBA::COMPLETED_YES, "other system exception");
  }
  try {
    echo->raise_it(4);
    check(true, "no exception");
  }
  catch (CORBA::UNKNOWN&) {
    check(true, "servant bug");  // the Python servant raises a non-IDL exception
  }

  CORBA::Long before = echo->fired();
  echo->fire(3);
  echo->fire(4);
  CORBA::Long after = before;
  for (int i = 0; i < 500 && after != before + 7; ++i) {
    omni_thread::sleep(0, 10000000);
    after = echo->fired();
  }
  check(after == before + 7, "oneway");

  Peer::Echo_var self = echo->myself();
  CORBA::String_var back = self->echo_text("again");
  check(std::strcmp(back, "again") == 0, "object reference result");

  CallbackImpl* cb_impl = new CallbackImpl;
  Peer::Callback_var cb = cb_impl->_this();
  CORBA::String_var got = echo->call_back(cb, "ping");
  check(std::strcmp(got, "cpp got ping") == 0, "callback", std::string(got));

  Peer::CallbackSeq cbs;
  cbs.length(2);
  cbs[0] = Peer::Callback::_duplicate(cb);
  cbs[1] = Peer::Callback::_nil();
  Peer::CallbackSeq_var cbr = echo->echo_callbacks(cbs);
  bool cbs_ok = cbr->length() == 2 && CORBA::is_nil(cbr[1]);
  if (cbs_ok) {
    CORBA::String_var via = cbr[0]->notify("again");
    cbs_ok = std::strcmp(via, "cpp got again") == 0;
  }
  check(cbs_ok, "sequence of references");

  Peer::Echo_var swapped = Peer::Echo::_duplicate(self);
  echo->swap_echo(swapped.inout());
  CORBA::String_var via_swapped = swapped->echo_text("swapped");
  check(std::strcmp(via_swapped, "swapped") == 0, "inout reference");

  CORBA::Object_var same_obj = echo->echo_object(echo);
  check(same_obj->_is_equivalent(echo), "Object argument");
  CORBA::Object_var nil = echo->echo_object(CORBA::Object::_nil());
  check(CORBA::is_nil(nil), "nil Object");

  echo->counter(41);
  check(echo->counter() == 41, "attribute");
  CORBA::String_var label = echo->label();
  check(std::strlen(label) > 0, "readonly attribute");

  check(echo->_is_a("IDL:Peer/Echo:1.0") && !echo->_is_a("IDL:Peer/Callback:1.0"), "_is_a");
  check(!echo->_non_existent(), "_non_existent");

  std::cout << (failures ? "FAILED" : "ALL PASSED") << std::endl;
  return failures ? 1 : 0;
}

static CosEventChannelAdmin::EventChannel_ptr channel(CORBA::ORB_ptr orb, const std::string& name)
{
  CosNaming::NamingContext_var ctx = root(orb);
  CORBA::Object_var obj = ctx->resolve(to_name(name));
  return CosEventChannelAdmin::EventChannel::_narrow(obj);
}

static int push(CORBA::ORB_ptr orb, const std::string& name, int n)
{
  CosEventChannelAdmin::EventChannel_var ch = channel(orb, name);
  CosEventChannelAdmin::SupplierAdmin_var admin = ch->for_suppliers();
  CosEventChannelAdmin::ProxyPushConsumer_var proxy = admin->obtain_push_consumer();
  proxy->connect_push_supplier(CosEventComm::PushSupplier::_nil());
  for (int i = 0; i < n; ++i) {
    Peer::Point p;
    p.x = i;
    p.y = 2 * i;
    CORBA::Any a;
    a <<= p;
    proxy->push(a);
  }
  CORBA::Any last;
  last <<= make_nested(n);
  proxy->push(last);
  std::cout << "PUSHED " << n + 1 << std::endl;
  proxy->disconnect_push_consumer();
  return 0;
}

class Consumer : public POA_CosEventComm::PushConsumer
{
public:
  Consumer(int n) : left_(n) {}
  void push(const CORBA::Any& data)
  {
    const Peer::Point* p;
    const Peer::Nested* nested;
    CORBA::Long l;
    const char* s;
    if (data >>= p)
      std::cout << "EVENT Point " << p->x << " " << p->y << std::endl;
    else if (data >>= nested)
      std::cout << "EVENT Nested " << nested->name << " " << nested->last << std::endl;
    else if (data >>= l)
      std::cout << "EVENT long " << l << std::endl;
    else if (data >>= s)
      std::cout << "EVENT string " << s << std::endl;
    else {
      CORBA::TypeCode_var tc = data.type();
      std::cout << "EVENT other " << (tc->kind()) << std::endl;
    }
    --left_;
  }
  void disconnect_push_consumer() {}
  int left_;
};

static int consume(CORBA::ORB_ptr orb, const std::string& name, int n)
{
  activate_poa(orb);
  CosEventChannelAdmin::EventChannel_var ch = channel(orb, name);
  CosEventChannelAdmin::ConsumerAdmin_var admin = ch->for_consumers();
  CosEventChannelAdmin::ProxyPushSupplier_var proxy = admin->obtain_push_supplier();
  Consumer* consumer = new Consumer(n);
  CosEventComm::PushConsumer_var ref = consumer->_this();
  proxy->connect_push_consumer(ref);
  std::cout << "CONNECTED" << std::endl;
  while (consumer->left_ > 0) omni_thread::sleep(0, 10000000);
  proxy->disconnect_push_supplier();
  return 0;
}

static int bench(CORBA::ORB_ptr orb, const std::string& name, int n)
{
  Peer::Echo_var echo = resolve_echo(orb, name);
  std::vector<double> a, b;
  for (int i = 0; i < n; ++i) {
    auto t0 = std::chrono::steady_clock::now();
    echo->nothing();
    auto t1 = std::chrono::steady_clock::now();
    CORBA::String_var s = echo->echo_text("hello");
    auto t2 = std::chrono::steady_clock::now();
    a.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
    b.push_back(std::chrono::duration<double, std::micro>(t2 - t1).count());
  }
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  std::cout << "P50 " << a[a.size() / 2] << " " << b[b.size() / 2] << std::endl;
  return 0;
}

int main(int argc, char** argv)
{
  try {
    CORBA::ORB_var orb = CORBA::ORB_init(argc, argv);
    if (argc < 3) {
      std::cerr << "usage: peer server|client|push|consume|bench NAME [N]" << std::endl;
      return 2;
    }
    std::string mode = argv[1], name = argv[2];
    int n = argc > 3 ? std::atoi(argv[3]) : 0;
    int rc = 2;
    if (mode == "server") {
      CORBA::Object_var obj = orb->resolve_initial_references("RootPOA");
      rc = serve(orb, name == "-" ? "" : name);
    }
    else if (mode == "client") rc = client(orb, name);
    else if (mode == "push") rc = push(orb, name, n);
    else if (mode == "consume") rc = consume(orb, name, n);
    else if (mode == "bench") rc = bench(orb, name, n);
    orb->destroy();
    return rc;
  }
  catch (CORBA::SystemException& e) {
    std::cout << "FAIL CORBA::" << e._name() << " minor " << e.minor() << std::endl;
  }
  catch (CORBA::Exception& e) {
    std::cout << "FAIL CORBA::" << e._name() << std::endl;
  }
  return 1;
}
