// Requests to the kea server. A server started with --token (KEA_TOKEN) answers
// 401 without `Authorization: Bearer <token>`: the page then asks for the token once,
// keeps it for this tab (sessionStorage, never in the URL) and sends it on every
// request. Job events are read from a fetch stream, because EventSource cannot send
// an Authorization header.

export const TOKEN_KEY = 'kea-token';

/** fetch() with the token; on a 401, ask for the token and try once more. */
export async function api(path, init = {}) {
  for (let attempt = 0; ; attempt++) {
    const headers = new Headers(init.headers);
    const token = sessionStorage.getItem(TOKEN_KEY);
    if (token) headers.set('authorization', `Bearer ${token}`);
    const response = await fetch(path, { ...init, headers });
    if (response.status !== 401 || attempt > 0) return response;
    const given = window.prompt(
      token
        ? 'The kea server refused the access token. Its token (--token / KEA_TOKEN):'
        : 'This kea server needs its access token (--token / KEA_TOKEN):',
    );
    if (!given?.trim()) return response;
    sessionStorage.setItem(TOKEN_KEY, given.trim());
  }
}

/**
 * The server-sent events at `path` as {event, data} until the server ends the
 * stream or `signal` aborts it. Throws the response when it is not a stream.
 */
export async function* events(path, signal) {
  const response = await api(path, { headers: { accept: 'text/event-stream' }, signal });
  if (!response.ok || !response.body) throw response;
  const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
  let buffer = '';
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return;
    buffer += value.replace(/\r\n?/g, '\n');
    let end;
    while ((end = buffer.indexOf('\n\n')) >= 0) {
      const block = buffer.slice(0, end);
      buffer = buffer.slice(end + 2);
      let event = 'message';
      const data = [];
      for (const line of block.split('\n')) {
        if (line === '' || line.startsWith(':')) continue; // comment (keep-alive)
        const colon = line.indexOf(':');
        const field = colon < 0 ? line : line.slice(0, colon);
        const text = colon < 0 ? '' : line.slice(colon + 1).replace(/^ /, '');
        if (field === 'event') event = text;
        else if (field === 'data') data.push(text);
      }
      if (data.length) yield { event, data: data.join('\n') };
    }
  }
}
