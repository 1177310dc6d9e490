/* The host owns the threads, through the C ABI (ss_task_system): an in-process server and a
 * remote session whose background work runs as tasks of a small pthread pool written here, as an
 * engine's job system would take it. Checks that the work ran there, that the answers are the
 * server's usual ones, that a bad task system is refused, and that destroying the sessions leaves
 * no task behind. */

#define _POSIX_C_SOURCE 199309L /* nanosleep */
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "softshell/softshell_c.h"
#include "softshell/softshell_embedded_c.h"

#include "c_check.h"

/* ---- a host job system: a fixed pool of pthreads over a linked queue ---- */

typedef struct job {
  ss_task_fn fn;
  void* data;
  struct job* next;
} job;

typedef struct pool {
  pthread_mutex_t mu;
  pthread_cond_t cv;
  job *head, *tail;
  int stopping;
  pthread_t threads[4];
  int size;
  atomic_int enqueued, ran;
} pool;

static void* worker(void* arg) {
  pool* p = (pool*)arg;
  for (;;) {
    pthread_mutex_lock(&p->mu);
    while (!p->head && !p->stopping) pthread_cond_wait(&p->cv, &p->mu);
    job* j = p->head;
    if (!j) { /* stopping and drained */
      pthread_mutex_unlock(&p->mu);
      return NULL;
    }
    p->head = j->next;
    if (!p->head) p->tail = NULL;
    pthread_mutex_unlock(&p->mu);
    j->fn(j->data);
    atomic_fetch_add(&p->ran, 1);
    free(j);
  }
}

static void enqueue(ss_task_fn fn, void* data, void* user) {
  pool* p = (pool*)user;
  job* j = (job*)malloc(sizeof *j);
  j->fn = fn;
  j->data = data;
  j->next = NULL;
  atomic_fetch_add(&p->enqueued, 1);
  pthread_mutex_lock(&p->mu);
  if (p->tail) p->tail->next = j;
  else p->head = j;
  p->tail = j;
  pthread_cond_signal(&p->cv);
  pthread_mutex_unlock(&p->mu);
}

static void pool_start(pool* p, int size) {
  memset(p, 0, sizeof *p);
  pthread_mutex_init(&p->mu, NULL);
  pthread_cond_init(&p->cv, NULL);
  p->size = size;
  for (int i = 0; i < size; ++i) pthread_create(&p->threads[i], NULL, worker, p);
}

static void pool_stop(pool* p) {
  pthread_mutex_lock(&p->mu);
  p->stopping = 1;
  pthread_cond_broadcast(&p->cv);
  pthread_mutex_unlock(&p->mu);
  for (int i = 0; i < p->size; ++i) pthread_join(p->threads[i], NULL);
  pthread_cond_destroy(&p->cv);
  pthread_mutex_destroy(&p->mu);
}

/* ---- the scene: a flat plate (make_grid) pinned at its corners, pushed in the middle ---- */

enum { N = 6, NV = (N + 1) * (N + 1) };

static ss_request* make_push(void) {
  ss_request* r = NULL;
  CHECK_OK(ss_request_create(&r));
  const ss_vec3 zero = {0, 0, 0}, down = {0, 0, -50.0};
  const int32_t corners[4] = {0, N, NV - 1 - N, NV - 1};
  for (int k = 0; k < 4; ++k) CHECK_OK(ss_request_add_vertex_constraint(r, corners[k], 7, &zero));
  CHECK_OK(ss_request_add_force(r, (N / 2) * (N + 1) + N / 2, &down));
  return r;
}

static void sleep_ms(int ms) {
  struct timespec ts = {0, ms * 1000000L};
  nanosleep(&ts, NULL);
}

/* Deforms asynchronously, polling as a frame loop does; the deformed points into `out`. */
static int deform_polled(ss_session* session, const ss_geom_id* id, const ss_request* request, double* out) {
  ss_deformation* op = NULL;
  if (ss_session_deform_begin(session, id, request, &op) != SS_OK) return 0;
  int32_t ready = 0;
  for (int frame = 0; frame < 60000 && !ready; ++frame) {
    CHECK_OK(ss_deformation_poll(op, &ready));
    if (!ready) sleep_ms(1);
  }
  uint32_t res_id = 0;
  int32_t count = 0;
  const int ok = ready && ss_deformation_read(op, &res_id, out, NV, &count) == SS_OK && count == NV;
  ss_deformation_destroy(op);
  return ok;
}

int main(void) {
  pool server_pool, client_pool;
  pool_start(&server_pool, 2);
  pool_start(&client_pool, 1);
  const ss_task_system server_tasks = {enqueue, 2, &server_pool};
  const ss_task_system client_tasks = {enqueue, 1, &client_pool};

  /* A bad task system is refused with a message. */
  ss_session* bad = NULL;
  const ss_task_system no_enqueue = {NULL, 2, NULL}, no_threads = {enqueue, 0, &server_pool};
  CHECK(ss_session_create_embedded_on(NULL, &no_enqueue, &bad) == SS_INVALID_ARGUMENT && bad == NULL);
  CHECK(strstr(ss_last_error_message(), "enqueue") != NULL);
  CHECK(ss_session_create_embedded_on(NULL, &no_threads, &bad) == SS_INVALID_ARGUMENT && bad == NULL);
  CHECK(strstr(ss_last_error_message(), "concurrency") != NULL);

  ss_embedded_options options;
  ss_embedded_options_default(&options);
  options.listen = 1;
  options.worker_threads = 1;
  ss_session* server = NULL;
  CHECK_OK(ss_session_create_embedded_on(&options, &server_tasks, &server));
  int32_t port = 0;
  CHECK_OK(ss_session_embedded_port(server, &port));
  char url[64];
  snprintf(url, sizeof url, "http://127.0.0.1:%d", (int)port);
  ss_session* remote = NULL;
  CHECK_OK(ss_session_create_remote_on(url, NULL, &client_tasks, &remote));
  CHECK(ss_session_create_remote_on(url, NULL, &no_enqueue, &bad) == SS_INVALID_ARGUMENT && bad == NULL);

  ss_mesh* mesh = make_grid(N);
  const ss_material material = {7.0e10, 0.3, 0.01, 2700.0};
  ss_geom_id id;
  CHECK_OK(ss_session_upload(server, mesh, &material, NULL, &id, NULL));
  ss_request* push = make_push();
  double embedded_xyz[3 * NV], remote_xyz[3 * NV], rest[3 * NV];
  CHECK(deform_polled(server, &id, push, embedded_xyz));
  const int server_tasks_after_one = atomic_load(&server_pool.enqueued);
  CHECK(server_tasks_after_one >= 2); /* the precomputation and the solve */
  CHECK(deform_polled(remote, &id, push, remote_xyz));
  CHECK(atomic_load(&client_pool.enqueued) >= 1); /* the remote request ran on the client pool */

  int32_t count = 0;
  CHECK_OK(ss_mesh_positions(mesh, rest, NV, &count));
  const int centre = (N / 2) * (N + 1) + N / 2;
  const double dent = embedded_xyz[3 * centre + 2] - rest[3 * centre + 2];
  double worst = 0.0;
  for (int k = 0; k < 3 * NV; ++k) worst = fmax(worst, fabs(embedded_xyz[k] - remote_xyz[k]));
  CHECK(dent < 0.0);
  CHECK(worst <= 1e-6 * fabs(dent)); /* the remote answer (JSON, double precision) is the same */
  for (int k = 0; k < 4; ++k) {
    const int corner = (int[]){0, N, NV - 1 - N, NV - 1}[k];
    CHECK(embedded_xyz[3 * corner + 2] == rest[3 * corner + 2]);
  }

  ss_request_destroy(push);
  ss_mesh_destroy(mesh);
  ss_session_destroy(remote);
  ss_session_destroy(server); /* waits for the server's tasks, which the pool still runs */
  pool_stop(&client_pool);
  pool_stop(&server_pool);
  CHECK(atomic_load(&server_pool.ran) == atomic_load(&server_pool.enqueued));
  CHECK(atomic_load(&client_pool.ran) == atomic_load(&client_pool.enqueued));
  printf("c_api_tasks_test: %d server tasks, %d client tasks; %d checks, %d failures\n",
         atomic_load(&server_pool.ran), atomic_load(&client_pool.ran), g_checks, g_failures);
  return g_failures == 0 ? 0 : 1;
}
