// Signing in and out. The token is sent once, to /api/sign-in, and never kept: the backend
// answers with an HttpOnly cookie this script cannot read. Every request that changes
// anything carries X-Landscape-Request (a header no form and no other origin's page can
// send), and the backend checks the Origin too (supervisor_gui_web/http_guard.py).
const $ = (id) => document.getElementById(id);
const HEADERS = { 'X-Landscape-Request': 'page' };

// {name, role, idle_s, max_age_s} of the person signed in, or null.
export async function whoAmI() {
  const reply = await fetch('/api/me', { credentials: 'same-origin' });
  if (reply.status === 401) return null;
  if (!reply.ok) throw new Error(`the supervisor answered ${reply.status} to /api/me`);
  return reply.json();
}

// The sign-in form instead of the page; `why` says why it is shown (a sign-in that ended).
export function showSignIn(why = '') {
  $('app').hidden = true;
  $('sign-in').hidden = false;
  $('sign-in-why').textContent = why;
  const form = $('sign-in-form');
  const input = $('sign-in-token');
  input.focus();
  form.onsubmit = async (event) => {
    event.preventDefault();
    const token = input.value.trim();
    input.value = '';   // the page keeps no token
    if (!token) return;
    const reply = await fetch('/api/sign-in', {
      method: 'POST', credentials: 'same-origin',
      headers: { ...HEADERS, 'Content-Type': 'application/json' },
      body: JSON.stringify({ token }),
    });
    if (reply.ok) { location.reload(); return; }
    const text = reply.headers.get('Content-Type')?.includes('json') ? (await reply.json()).error : await reply.text();
    $('sign-in-error').textContent = `Not signed in: ${text}`;
  };
}

export async function signOut() {
  await fetch('/api/sign-out', { method: 'POST', credentials: 'same-origin', headers: HEADERS });
  location.reload();
}

// The header's line: who is signed in, as what, and the way out.
export function showPerson(person) {
  $('person').textContent = `${person.name} (${person.role})`;
  $('person').className = `pill role-${person.role}`;
  $('btn-sign-out').hidden = false;
  $('btn-sign-out').onclick = () => signOut();
}
