// ThreadSanitizer suppressions of the test executables that run a server, and of softshell-server
// in a ThreadSanitizer build (compiled into each: the runtime looks the function up in the
// executable).
//
// Debian's libcpp-httplib.so is not built with ThreadSanitizer. Its function-local statics (e.g.
// the set of method names in Server::parse_request_line) are initialized by the first connection
// thread and read by the others through the inlined, uninstrumented fast path of the static
// guard, so ThreadSanitizer sees the reads (through its memcmp interceptor) but not the
// acquire that orders them: a false positive. Only accesses that the library itself makes
// through an interceptor are suppressed; our own code stays fully checked.
//
// std::ctype<char>::narrow fills a per-locale cache without synchronization (libstdc++'s known
// benign race, GCC PR 77704); std::regex construction (cpp-httplib's client parses URLs with
// one) reaches it from several threads.
//
// RemoteSession's event stream is ended from another thread with httplib::Client::stop (which
// cpp-httplib provides for that). The uninstrumented library takes and releases the client's
// socket mutex inside stop(); ThreadSanitizer records only the release (the lock is made by the
// library, whose interceptor calls are ignored above) and reports "unlock of an unlocked mutex"
// in StreamSource::join (remote_events.cpp). Only mutex reports there are suppressed; races
// stay reported.
//
// CHOLMOD runs parallel regions through libgomp, whose barriers (futexes in an uninstrumented
// library) ThreadSanitizer cannot see; accesses CHOLMOD and libgomp make through interceptors
// (memset, memcpy) are suppressed for the same reason.
extern "C" const char* __tsan_default_suppressions() {
  return "called_from_lib:libcpp-httplib.so\n"
         "called_from_lib:libgomp.so\n"
         "called_from_lib:libcholmod.so\n"
         "race:std::ctype<char>::narrow\n"
         "mutex:sdk/net/src/remote_events.cpp\n";
}
