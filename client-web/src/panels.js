// Panels that fold away: each panel is a <details> whose <summary> is its title; a click (or Enter) on the
// title folds it to the title or opens it again. What a person chose is kept in localStorage, per panel;
// a panel nobody chose for starts open on a large screen and folded on a small one, except those the page
// marks `data-small="open"` (the legend, the replay's timeline), so that a phone shows the body first.

const KEY = 'tactile.panels';

// The state to start a panel in: the stored choice, else the default for the screen.
/**
 * @param {string} id @param {{ [id: string]: boolean }} stored @param {boolean} small
 * @param {boolean} openWhenSmall
 */
export function initialOpen(id, stored, small, openWhenSmall) {
  if (typeof stored[id] === 'boolean') return stored[id];
  return small ? openWhenSmall : true;
}

export class Panels {
  // `root`: where the panels are (details.panel with an id); `small`: whether the screen is a phone's.
  /** @param {ParentNode} root @param {boolean} small @param {Storage | null} [storage] */
  constructor(root, small, storage = globalThis.localStorage ?? null) {
    this.storage = storage;
    this.small = small;
    /** @type {HTMLDetailsElement[]} */
    this.panels = Array.from(root.querySelectorAll('details.panel[id]'));
    /** @type {{ [id: string]: boolean }} */
    this.stored = this.load();
    /** @type {Set<string>} */
    this.byPerson = new Set(); // panels whose next toggle a person made (a title clicked)
    for (const p of this.panels) {
      p.open = initialOpen(p.id, this.stored, small, p.dataset.small === 'open');
      const title = p.querySelector(':scope > summary');
      if (title) title.addEventListener('click', () => this.byPerson.add(p.id));
      // (The toggle event comes after the change, in a task of its own, for a script's change too.)
      p.addEventListener('toggle', () => {
        if (!this.byPerson.delete(p.id)) return;
        this.remember(p);
        if (this.small && p.open && p.dataset.small !== 'open') this.foldOthers(p);
      });
    }
  }

  /** @returns {{ [id: string]: boolean }} */
  load() {
    try {
      const v = JSON.parse(this.storage?.getItem(KEY) || '{}');
      return v && typeof v === 'object' ? v : {};
    } catch {
      return {};
    }
  }

  /** @param {HTMLDetailsElement} p */
  remember(p) {
    this.stored[p.id] = p.open;
    try {
      this.storage?.setItem(KEY, JSON.stringify(this.stored));
    } catch {
      // (Storage refused, e.g. a private window's quota: the page works without remembering.)
    }
  }

  // On a small screen one large panel is open at a time: opening one folds the others of its kind.
  /** @param {HTMLDetailsElement} opened */
  foldOthers(opened) {
    for (const p of this.panels) {
      if (p !== opened && p.open && p.dataset.small !== 'open') {
        p.open = false;
        this.remember(p);
      }
    }
  }

  // Folds every panel when any is open, else opens them all (a key: the body alone, for a projector).
  toggleAll() {
    const open = !this.panels.some((p) => p.open && !p.hidden);
    for (const p of this.panels) {
      p.open = open;
      this.remember(p);
    }
  }
}
