#pragma once
// The access-token check of every request (private to the HTTP layer; server.cpp calls it first
// in its pre-routing and `Expect: 100-continue` handlers).
#include <string>

#include "listener.h"  // last: httplib.h (see listener.h)

namespace softshell::http::internal {

// True if the request may go on: no token configured, a request exempt from it (auth.h's
// list), or the right `Authorization: Bearer` header. Otherwise `res` holds the 401 answer
// (and the connection closes after it when the request has a body, which stays unread).
bool authorize(const std::string& token, const httplib::Request& req, httplib::Response& res);

}  // namespace softshell::http::internal
