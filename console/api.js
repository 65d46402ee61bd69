// The daemon's public API as the console uses it: JSON with revisions (ETag / If-Match), the
// bearer token when the daemon asks for one, and the change feed. The feed is read with fetch
// rather than EventSource because EventSource cannot send the Authorization header.

export class ApiError extends Error {
  constructor(status, body) {
    super(body && body.error ? body.error : `HTTP ${status}`);
    this.status = status;
    this.field = body && body.field;
    this.current = body && body.current_revision;
  }
  // "field: reason", as the daemon names the part of the request at fault.
  describe() {
    return this.field ? `${this.field}: ${this.message}` : this.message;
  }
}

// The daemon could not be reached at all (stopped, restarting, the network down): nothing
// was done. Said as such, not as the browser's "Failed to fetch".
export class Unreachable extends Error {
  constructor(method) {
    super(method === 'GET' ? 'the daemon cannot be reached' : 'not saved: the daemon cannot be reached');
    this.write = method !== 'GET';
  }
}

export function revisionOf(etag) {
  const m = /^(?:W\/)?"(\d+)"$/.exec(etag || '');
  return m ? Number(m[1]) : null;
}

// How often a request the daemon is too busy for is tried again (about a minute in all).
// onBusy(path) is told of each wait, and onBusy(null) when the request went through.
const BUSY_RETRIES = 60;

export class Api {
  constructor(token = '') {
    this.token = token;
    this.onBusy = () => {};
    // Writes that never reached the daemon, since the console last said so.
    this.lostWrites = 0;
  }

  headers(extra = {}) {
    const h = { ...extra };
    if (this.token) h.Authorization = `Bearer ${this.token}`;
    return h;
  }

  async request(method, path, { body, revision, accept } = {}) {
    const headers = this.headers();
    if (body !== undefined) headers['Content-Type'] = 'application/json';
    if (revision !== undefined && revision !== null) headers['If-Match'] = `"${revision}"`;
    if (accept) headers.Accept = accept;
    // The daemon runs heavy work on two workers and answers 503 with Retry-After beyond them;
    // nothing was done then, so asking again is safe for every route.
    let resp;
    for (let attempt = 0; ; attempt++) {
      try {
        resp = await fetch(path, {
          method,
          headers,
          body: body === undefined ? undefined : JSON.stringify(body),
          cache: 'no-store',
        });
      } catch {
        if (method !== 'GET') this.lostWrites++;
        throw new Unreachable(method);
      }
      if (resp.status !== 503 || attempt >= BUSY_RETRIES) {
        if (attempt > 0) this.onBusy(null);
        break;
      }
      const wait = Math.min(5, Number(resp.headers.get('Retry-After')) || 1);
      this.onBusy(path);
      await new Promise((r) => setTimeout(r, wait * 1000 * (0.5 + Math.random() / 2)));
    }
    if (!resp.ok) {
      let err = null;
      try {
        err = await resp.json();
      } catch {
        err = { error: `HTTP ${resp.status}` };
      }
      if (resp.status === 412 && err.current_revision === undefined) {
        err.current_revision = revisionOf(resp.headers.get('ETag'));
      }
      throw new ApiError(resp.status, err);
    }
    return resp;
  }

  async get(path) {
    const resp = await this.request('GET', path);
    return { body: await resp.json(), revision: revisionOf(resp.headers.get('ETag')) };
  }

  async write(method, path, body, revision) {
    const resp = await this.request(method, path, { body, revision });
    return { body: await resp.json(), revision: revisionOf(resp.headers.get('ETag')) };
  }

  // An image or a file, as a Blob, with the response's headers.
  async blob(path) {
    const resp = await this.request('GET', path);
    return { blob: await resp.blob(), headers: resp.headers };
  }

  // Calls onChange(change) for every change on the feed until stop() is called; reconnects
  // after a second when the connection drops, and reports the connection's state.
  feed(onChange, onState = () => {}) {
    let stopped = false;
    let controller = null;
    const run = async () => {
      while (!stopped) {
        controller = new AbortController();
        try {
          const resp = await fetch('/v1/events', {
            headers: this.headers({ Accept: 'text/event-stream' }),
            signal: controller.signal,
            cache: 'no-store',
          });
          if (!resp.ok) throw new ApiError(resp.status, await resp.json().catch(() => null));
          onState('live');
          const reader = resp.body.pipeThrough(new TextDecoderStream()).getReader();
          let buffer = '';
          for (;;) {
            const { value, done } = await reader.read();
            if (done) break;
            buffer += value;
            let end;
            while ((end = buffer.indexOf('\n\n')) >= 0) {
              const event = parseEvent(buffer.slice(0, end));
              buffer = buffer.slice(end + 2);
              if (event && event.name === 'change') onChange(event.data);
            }
          }
        } catch (e) {
          if (stopped) return;
          onState(e instanceof ApiError && e.status === 401 ? 'token' : 'offline');
        }
        if (!stopped) {
          onState('offline');
          await new Promise((r) => setTimeout(r, 1000));
        }
      }
    };
    run();
    return () => {
      stopped = true;
      if (controller) controller.abort();
    };
  }
}

// One Server-Sent Event block: its name and its data parsed as JSON (null for comments and
// keep-alives).
export function parseEvent(block) {
  let name = 'message';
  const data = [];
  for (const line of block.split('\n')) {
    if (line.startsWith(':')) continue;
    const colon = line.indexOf(':');
    const field = colon < 0 ? line : line.slice(0, colon);
    let value = colon < 0 ? '' : line.slice(colon + 1);
    if (value.startsWith(' ')) value = value.slice(1);
    if (field === 'event') name = value;
    else if (field === 'data') data.push(value);
  }
  if (!data.length) return null;
  try {
    return { name, data: JSON.parse(data.join('\n')) };
  } catch {
    return null;
  }
}
