// ESLint (flat config): the recommended rules, and the ones this code already keeps, for the hand-written
// codec (src/index.ts, through typescript-eslint) and the node scripts, tests and bench. src/generated/ is
// flatc's (scripts/generate.js), not linted. No stylistic rules: the formatting stays as it is.
import js from '@eslint/js';
import { defineConfig } from 'eslint/config';
import globals from 'globals';
import tseslint from 'typescript-eslint';

export default defineConfig(
  { ignores: ['dist/', 'src/generated/'] },
  js.configs.recommended,
  {
    languageOptions: { ecmaVersion: 2022, sourceType: 'module' },
    linterOptions: { reportUnusedDisableDirectives: 'error' },
    rules: {
      eqeqeq: 'error',
      'no-var': 'error',
      'prefer-const': ['error', { destructuring: 'all' }],
      'object-shorthand': 'error',
      'no-throw-literal': 'error',
      'prefer-promise-reject-errors': 'error',
      'array-callback-return': 'error',
      'no-self-compare': 'error',
      'no-template-curly-in-string': 'error',
      'no-duplicate-imports': 'error',
      'no-eval': 'error',
      'no-implied-eval': 'error',
      'no-new-func': 'error',
      'no-return-assign': 'error',
    },
  },
  { files: ['src/**/*.ts'], extends: [tseslint.configs.recommended] },
  { files: ['**/*.js'], languageOptions: { globals: globals.node } },
);
